"""Run SLAM and mapping on a ROS bag: a rosbag2 recording (``.mcap``, ``.db3`` or its
folder) or a ROS 1 ``.bag``, through the same localizer and mapper stages as every other
source (:func:`acslam.replay.localize`, :mod:`acslam.replay.outputs`).

Robots: one at the root (topics ``/scan``, ``/odom``, ``/tf_static``) or one per
namespace (``/<ns>/scan``, ``/<ns>/odom``, and ``/<ns>/tf_static`` or the global
``/tf_static``), robot ``i`` being the ``i``-th namespace. Topic names resolve as ROS
resolves them: a relative name under the namespace, an absolute one as it is. A robot
may also publish landmark points (``landmarks``, ``sensor_msgs/PointCloud2``, x y z in
its base frame).

Each robot's state is its laser frame, as in the CARMEN replay: the laser's mount in the
base frame (the odometry's child frame) comes from the static transforms joining the two
(:class:`~acslam.ros2.tf_tree.TfTree`), and odometry, scans and landmark frames become one
ordered stream per robot through :class:`~acslam.ros2.pairing.OdometryPairing`. The
robots' streams are merged in stamp order (at equal stamps robot by robot, odometry before
sensors, as the simulator sends them) and batched as the server receives a live team's,
from the first odometry stamp. Stamps are the bag's header stamps, in seconds. As every
replay, it ends the data with a last loop search and settling, unless told not to: a live
run never does, so a bag of ``acslam run --record`` replays without it to the run's own
estimate.

Start poses: each robot starts at its first odometry pose, its odometry frame taken as the
map frame. Robots whose odometry frames differ are therefore not aligned with each other
(nothing in a bag says how they are); :mod:`acslam.replay.unknown_starts` replays them
each in its own frame and merges their maps instead.

A robot without an odometry topic gets scan-matching odometry: each scan is matched to
the one before (:func:`~acslam.mapping.scan_matching.match_scans` with the algorithms'
scan matching), the previous increment being the guess, which stands where a match fails
verification; its base is then its laser frame.

Outputs: one TUM trajectory per robot (``trajectory.tum`` at the root,
``trajectory_<ns>.tum`` per namespace) of the robot's *base* (REP 105 ``base_link`` /
``base_footprint``): every kept scan's laser pose composed with the inverse mount,
stamped with the scan's header stamp; the map and figures of every laser replay; and
metrics.json.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig, ScanMatchingConfig
from acslam.errors import ConfigError, DataError, MessageError
from acslam.geometry import between, compose
from acslam.mapping.scan_matching import match_scans, prepare_scan, verify
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, RobotMessage
from acslam.pipeline.perception import KeptScan
from acslam.pipeline.stages import Localizer
from acslam.provenance import write_metrics
from acslam.replay import Replayed, localize
from acslam.replay.outputs import PosedScans, replay_metrics, write_maps
from acslam.ros2 import convert
from acslam.ros2.bag import BagMessage, BagReader, MemoryBag
from acslam.ros2.pairing import OdometryPairing
from acslam.ros2.source import Ros2Topics, resolve
from acslam.ros2.tf_tree import TfTree
from acslam.trajectory import write_tum

GLOBAL_TF_STATIC = "/tf_static"

_TYPES = {
    "scan": "sensor_msgs/msg/LaserScan",
    "odom": "nav_msgs/msg/Odometry",
    "landmarks": "sensor_msgs/msg/PointCloud2",
    "tf_static": "tf2_msgs/msg/TFMessage",
}


@dataclass
class BagRobot:
    """One robot's part of the bag, decoded."""

    index: int
    namespace: str
    odometry: list[tuple[float, np.ndarray]] = field(default_factory=list)
    scans: list[LidarScan] = field(default_factory=list)
    landmarks: list[LandmarkObservations] = field(default_factory=list)
    frames: dict[str, tuple[str, ...]] = field(default_factory=dict)
    tf: TfTree = field(default_factory=TfTree)

    @property
    def name(self) -> str:
        return self.namespace or "/"


def _subscriptions(
    namespaces: Sequence[str], topics: Ros2Topics
) -> dict[str, tuple[int | None, str]]:
    """Topic -> (robot, kind) for every topic the replay reads; robot None for the global
    ``/tf_static``, which every robot's tree gets."""
    subscriptions: dict[str, tuple[int | None, str]] = {GLOBAL_TF_STATIC: (None, "tf_static")}
    for index, namespace in enumerate(namespaces):
        for kind in ("scan", "odom", "landmarks", "tf_static"):
            topic = resolve(namespace, getattr(topics, kind))
            if topic == GLOBAL_TF_STATIC:
                continue
            if topic in subscriptions:
                raise ConfigError(None, f"{kind} topic", f"two robots would read {topic}")
            subscriptions[topic] = (index, kind)
    return subscriptions


def _read(
    bag: BagReader | MemoryBag, namespaces: Sequence[str], topics: Ros2Topics
) -> tuple[list[BagRobot], dict[str, str]]:
    """Every robot's messages from the bag, and the topics each robot was read from."""
    subscriptions = _subscriptions(namespaces, topics)
    robots = [BagRobot(index, namespace) for index, namespace in enumerate(namespaces)]
    for topic, (_, kind) in subscriptions.items():
        found = bag.topics.get(topic)
        if found is not None and found != _TYPES[kind]:
            raise DataError(bag.path, f"{topic}: expected {_TYPES[kind]}, found {found}")
    for robot in robots:
        scan_topic = resolve(robot.namespace, topics.scan)
        if scan_topic not in bag.topics:
            raise DataError(
                bag.path,
                f"no {scan_topic} topic ({_TYPES['scan']}) for robot {robot.name}; the bag "
                f"has {', '.join(sorted(bag.topics)) or 'no topics'}",
            )
    for item in bag.messages(set(subscriptions) & set(bag.topics)):
        index, kind = subscriptions[item.topic]
        try:
            if index is None:
                for robot in robots:
                    _take(robot, kind, item)
            else:
                _take(robots[index], kind, item)
        except MessageError as exc:
            raise DataError(bag.path, f"{item.topic}: {exc}") from None
    return robots, {t: kind for t, (_, kind) in subscriptions.items() if t in bag.topics}


def _take(robot: BagRobot, kind: str, item: BagMessage) -> None:
    """One decoded message into the robot's lists; each kind keeps the frames of its first
    message."""
    message = item.message
    if kind == "tf_static":
        for parent, child, _, pose in convert.tf_transforms(message):
            robot.tf.add(parent, child, pose)
        return
    if kind == "odom":
        stamp_s, pose, frame, child = convert.odometry_pose(message)
        frames = (frame, child)
        robot.odometry.append((stamp_s, pose))
    else:
        stamp_s, frames = convert.header_stamp_s(message), (convert.frame_id(message),)
        if kind == "scan":
            robot.scans.append(convert.laser_scan(message, robot.index, stamp_s))
        else:
            robot.landmarks.append(convert.landmark_observations(message, robot.index, stamp_s))
    first = robot.frames.setdefault(kind, frames)
    if first != frames:
        raise MessageError(f"frames {' -> '.join(frames)} after {' -> '.join(first)}")


def scan_matching_odometry(
    scans: Sequence[LidarScan], config: ScanMatchingConfig
) -> list[tuple[float, np.ndarray]]:
    """Odometry samples (stamp, laser pose) at every scan, from matching each scan to the
    one before; the first scan's pose is the origin. A match that fails verification
    leaves the previous increment (a constant velocity) in its place."""
    samples: list[tuple[float, np.ndarray]] = []
    reference = None
    pose = np.zeros(3)
    increment = np.zeros(3)
    for scan in sorted(scans, key=lambda s: s.stamp):
        prepared = prepare_scan(scan.angles, scan.ranges, config)
        if reference is not None:
            result = match_scans(reference, prepared, increment, config)
            if verify(result, increment, config, strict=False):
                increment = result.relative
            pose = compose(pose, increment)
        samples.append((scan.stamp, pose))
        reference = prepared
    return samples


def _mount(path: Path, robot: BagRobot) -> np.ndarray:
    """The laser's pose in the base frame, from the robot's static transforms."""
    base, laser = robot.frames["odom"][1], robot.frames["scan"][0]
    mount = robot.tf.lookup(base, laser)
    if mount is None:
        raise DataError(
            path,
            f"robot {robot.name}: no tf_static chain joins the odometry's child frame "
            f"{base!r} and the scan frame {laser!r}",
        )
    return mount


@dataclass(frozen=True)
class RobotStream:
    """A robot's messages for the localizer, with what they were made from: its laser
    mount, start (laser) pose and stamp, its first odometry pose (of the base, in the
    odometry frame), and the pairing that placed them."""

    robot: BagRobot
    mount: np.ndarray
    start: np.ndarray
    start_stamp_s: float
    odometry_start: np.ndarray
    messages: list[RobotMessage]
    pairing: OdometryPairing
    scan_matched: bool


def _stream(
    path: Path, robot: BagRobot, config: ScanMatchingConfig, own_frame: bool
) -> RobotStream:
    """The robot's odometry, scans and landmark frames paired into one ordered stream;
    with ``own_frame``, the robot starts at the origin of its own frame (its base there),
    not at its first odometry pose."""
    if not robot.scans:
        raise DataError(path, f"robot {robot.name}: its scan topic has no messages")
    scan_matched = not robot.odometry
    if scan_matched:
        odometry = scan_matching_odometry(robot.scans, config)
        mount, base = np.zeros(3), robot.frames["scan"][0]
    else:
        odometry = robot.odometry
        mount, base = _mount(path, robot), robot.frames["odom"][1]
    if robot.landmarks and robot.frames["landmarks"][0] != base:
        raise DataError(
            path,
            f"robot {robot.name}: landmarks in frame {robot.frames['landmarks'][0]!r}, "
            f"not the base frame {base!r}",
        )
    # At equal stamps odometry comes first, then the scan and landmarks: the simulator's order.
    events = sorted(
        [(stamp, 0, pose) for stamp, pose in odometry]
        + [(scan.stamp, 1, scan) for scan in robot.scans]
        + [(frame.stamp, 2, frame) for frame in robot.landmarks],
        key=lambda event: event[:2],
    )
    pairing = OdometryPairing(robot.index, mount)
    messages: list[RobotMessage] = []
    for stamp_s, kind, payload in events:
        if kind == 0:
            messages += pairing.odometry(stamp_s, payload)
        elif kind == 1:
            messages += pairing.scan(payload)
        else:
            messages += pairing.landmarks(payload)
    first_stamp_s, first_pose = min(odometry, key=lambda sample: sample[0])
    start = mount if own_frame else compose(first_pose, mount)
    return RobotStream(
        robot, mount, start, first_stamp_s, first_pose, messages, pairing, scan_matched
    )


def _dead_reckoned(stream: RobotStream) -> dict[int, np.ndarray]:
    """The laser pose by odometry alone at each of the stream's scans (by id)."""
    pose = stream.start
    at: dict[int, np.ndarray] = {}
    for message in stream.messages:
        if isinstance(message, OdometryIncrement):
            pose = compose(pose, message.delta)
        elif isinstance(message, LidarScan):
            at[id(message)] = pose
    return at


def _posed_scans(
    out_dir: Path, streams: Sequence[RobotStream], kept: Sequence[KeptScan], localizer: Localizer
) -> tuple[PosedScans, PosedScans]:
    """The kept scans at their SLAM and their odometry poses, for the maps; writes each
    robot's TUM trajectory of its base on the way."""
    slam_poses = [localizer.scan_pose(scan.index) for scan in kept]
    odometry_at = {k: v for stream in streams for k, v in _dead_reckoned(stream).items()}
    odometry_poses = [odometry_at[id(scan.received)] for scan in kept]
    slam_tracks, odometry_tracks = [], []
    for stream in streams:
        mine = [k for k, scan in enumerate(kept) if scan.received.robot_id == stream.robot.index]
        stamps = np.array([kept[k].received.stamp for k in mine])
        laser = np.array([slam_poses[k] for k in mine]).reshape(-1, 3)
        inverse_mount = between(stream.mount, np.zeros(3))
        base = np.array([compose(pose, inverse_mount) for pose in laser]).reshape(-1, 3)
        write_tum(out_dir / trajectory_name(stream.robot.namespace), stamps, base)
        slam_tracks.append(laser)
        odometry_tracks.append(np.array([odometry_poses[k] for k in mine]).reshape(-1, 3))
    return (
        PosedScans([scan.mappable for scan in kept], slam_poses, slam_tracks),
        PosedScans([scan.received for scan in kept], odometry_poses, odometry_tracks),
    )


def trajectory_name(namespace: str) -> str:
    return f"trajectory_{namespace.replace('/', '_')}.tum" if namespace else "trajectory.tum"


@dataclass(frozen=True)
class BagReplay:
    """A bag played through the localizer: each robot's stream, the topics read, the
    robots' messages merged as played from ``start_s``, the replay's result, and the
    seconds SLAM took."""

    streams: list[RobotStream]
    topics: dict[str, str]
    messages: list[RobotMessage]
    start_s: float
    replayed: Replayed
    slam_time_s: float

    @property
    def duration_s(self) -> float:
        """Seconds of recording played."""
        return self.messages[-1].stamp - self.start_s if self.messages else 0.0


def replay_bag(
    bag: BagReader | MemoryBag,
    *,
    namespaces: Sequence[str] = ("",),
    topics: Ros2Topics | None = None,
    algorithms: AlgorithmsConfig | None = None,
    finish: bool = True,
    own_frames: bool = False,
) -> BagReplay:
    """Play the robots of ``namespaces`` ("" = the root) through the localizer stage
    ``algorithms`` names (default: the simulated robots', a scenario's defaults); without
    ``finish``, no last loop search and settling at the end, as a live run ends (a bag of
    ``acslam run --record`` then replays to the run's own estimate). With
    ``own_frames``, each robot starts at the origin of its own frame."""
    algorithms = algorithms or AlgorithmsConfig()
    robots, read_topics = _read(bag, namespaces, topics or Ros2Topics())
    streams = [_stream(bag.path, robot, algorithms.scan_matching, own_frames) for robot in robots]
    messages = sorted(
        (message for stream in streams for message in stream.messages),
        key=lambda m: (m.stamp, m.robot_id),
    )
    start_s = min(stream.start_stamp_s for stream in streams)
    slam_start = time.perf_counter()
    starts = {stream.robot.index: stream.start for stream in streams}
    replayed = localize(messages, algorithms, starts, start_s, finish)
    slam_time_s = time.perf_counter() - slam_start
    return BagReplay(streams, read_topics, messages, start_s, replayed, slam_time_s)


def run_rosbag(
    path: str | Path,
    out_dir: str | Path,
    *,
    namespaces: Sequence[str] = ("",),
    topics: Ros2Topics | None = None,
    algorithms: AlgorithmsConfig | None = None,
    finish: bool = True,
    odometry_map: bool = True,
) -> dict:
    """Replay the bag at ``path`` (:func:`replay_bag`), map and write DIR/trajectory*.tum,
    map.yaml/.pgm/.png, odometry_vs_slam.png (unless ``odometry_map`` is False) and
    metrics.json."""
    algorithms = algorithms or AlgorithmsConfig()
    path, out_dir = Path(path), Path(out_dir)
    wall_start = time.perf_counter()
    with BagReader(path) as bag:
        replay = replay_bag(
            bag, namespaces=namespaces, topics=topics, algorithms=algorithms, finish=finish
        )
    kept, localizer = replay.replayed.scans, replay.replayed.localizer
    out_dir.mkdir(parents=True, exist_ok=True)
    slam, odometry = _posed_scans(out_dir, replay.streams, kept, localizer)
    replay_map = write_maps(
        out_dir, path.name, slam, odometry if odometry_map else None, algorithms
    )
    timings_s = {
        "wall_time_s": time.perf_counter() - wall_start,
        "slam_time_s": replay.slam_time_s,
    }
    metrics = {
        "bag": str(path),
        "topics": replay.topics,
        "robots": {
            stream.robot.name: robot_metrics(stream, kept, localizer) for stream in replay.streams
        },
        "trajectory_frame": "base (the odometry's child frame), one pose per kept scan",
        "finished": finish,
        **replay_metrics(localizer, replay_map, replay.duration_s, timings_s),
    }
    return write_metrics(out_dir, metrics)


def robot_metrics(stream: RobotStream, kept: Sequence[KeptScan], localizer: Localizer) -> dict:
    robot = stream.robot
    _, keyframe_poses = localizer.trajectory(robot.index)
    return {
        "trajectory": trajectory_name(robot.namespace),
        "odometry": "scan matching" if stream.scan_matched else "odometry topic",
        "frames": {kind: list(frames) for kind, frames in robot.frames.items()},
        "mount_xytheta": stream.mount.tolist(),
        "start_xytheta": stream.start.tolist(),
        "odometry_samples": len(robot.odometry),
        "scans": len(robot.scans),
        "scans_used": sum(1 for k in kept if k.received.robot_id == robot.index),
        "landmark_frames": len(robot.landmarks),
        "keyframes": len(keyframe_poses),
        "dropped": dict(stream.pairing.dropped),
    }
