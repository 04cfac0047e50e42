"""ROS 2 robots as a data source: the server's side of ``acslam serve --ros2``.

Per robot namespace (``/<ns>/...``, names resolved as ROS does: relative to the
namespace unless they start with ``/``) the source subscribes to ``scan``
(``sensor_msgs/LaserScan``), ``odom`` (``nav_msgs/Odometry``), optionally ``landmarks``
(``sensor_msgs/PointCloud2``, x y z in the base frame) and ``tf_static`` (the laser's
mount), and publishes ``cmd_vel``, ``tf`` (``map -> odom``, REP 105: never
``map -> base``) and ``plan``; for the team, ``/map`` (transient local, so a late RViz
still gets it; cropped to its known cells) and frontier, cluster and goal markers.

With unknown relative starts (:mod:`acslam.pipeline.frames`) ``map`` is still the team's
frame: robot 0's, where ``/map`` and the markers are. A robot not yet merged into it is
in the frame of its own (or its merged frame's first robot's) start, ``<ns>/map`` after
that robot's namespace: its ``tf`` has that parent and its plan that frame, and that
frame's map and markers go out under the namespace (``/<ns>/map``). A merge moves the
robot's ``odom`` under its new frame, and ``/tf_static`` (transient local) then holds
every merge so far as ``into -> merged`` frame at the pose the merge found, so what was
drawn in a merged frame still shows in place.

The robots keep their own clocks and odometry frames. Stamps become seconds since the
source started (:attr:`clock_origin_s`), odometry poses stay in each robot's ``odom``
frame: the server only uses their increments, from a start pose it is given in the map
frame. Scans and landmark frames are placed on the odometry time line by
:class:`~acslam.ros2.pairing.OdometryPairing`; the robot's state is its laser frame.

Nothing from the network is trusted: a message that does not decode, has a NaN, or names
a frame the robot's odometry and static transforms do not join is dropped and counted by
reason (:meth:`statistics`). A robot whose odometry stops for ``lost_after_s`` is reported
lost once. :meth:`stop` sends every robot zero velocity.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from acslam.errors import MessageError
from acslam.geometry import between, compose
from acslam.grid import GridSpec
from acslam.messages import RobotMessage
from acslam.pipeline.snapshot import MapView, Snapshot
from acslam.ros2 import convert, wire
from acslam.ros2.node import Ros2Node, Ros2Publisher, TopicStats
from acslam.ros2.pairing import OdometryPairing
from acslam.ros2.tf_tree import TfTree
from acslam.sources import LiveSource
from acslam.transport.zenoh_link import latency_percentiles_ms

SENSOR_QOS = wire.Qos(reliable=False, depth=5)  # rclcpp's SensorDataQoS, as laser drivers use
TF_STATIC_QOS = wire.Qos(transient_local=True, depth=1)
MAP_QOS = wire.Qos(transient_local=True, depth=1)  # nav2's map_server profile
ZERO_VELOCITY_REPEATS = 3


@dataclass(frozen=True)
class Ros2Topics:
    """Topic names; relative ones resolve under each robot's namespace."""

    scan: str = "scan"
    odom: str = "odom"
    landmarks: str = "landmarks"
    tf_static: str = "tf_static"
    cmd_vel: str = "cmd_vel"
    tf: str = "tf"
    plan: str = "plan"
    ground_truth: str = "ground_truth"
    map: str = "/map"
    markers: str = "/exploration_markers"
    # cmd_vel as TwistStamped (True) or Twist (False); None: the distro's (cmd_vel_type).
    cmd_vel_stamped: bool | None = None


def resolve(namespace: str, name: str) -> str:
    """A ROS name under ``namespace`` (``robot1``, ``scan`` -> ``/robot1/scan``)."""
    if name.startswith("/"):
        return name
    return f"/{namespace.strip('/')}/{name}" if namespace.strip("/") else f"/{name}"


def cmd_vel_type(distro: str, stamped: bool | None) -> str:
    """``Twist`` on Humble, ``TwistStamped`` from Jazzy on (what ros2_control's diff drive
    controller requires there; Nav2 with ``enable_stamped_cmd_vel``), unless ``stamped``
    says otherwise."""
    if stamped is None:
        stamped = distro != "humble"
    return "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist"


@dataclass
class _Robot:
    """What the source knows of one robot; the callbacks fill ``inbox`` under the lock."""

    index: int
    namespace: str
    tf: TfTree = field(default_factory=TfTree)
    inbox: list[tuple[str, str, object]] = field(default_factory=list)  # topic, kind, msg
    base_frame: str | None = None
    odom_frame: str | None = None
    scan_frame: str | None = None
    latest_odometry: tuple[float, np.ndarray] | None = None  # ROS stamp, before the start
    pairing: OdometryPairing | None = None
    heard_wall_s: float = -math.inf
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)
    last_plan: object = None

    def joins_base(self, frame: str | None) -> bool:
        """Whether static transforms place ``frame`` in the odometry's base frame."""
        return (
            frame is not None
            and self.base_frame is not None
            and self.tf.lookup(self.base_frame, frame) is not None
        )

    def take_scan_frame(self, frame: str) -> None:
        """Before the start, the scan frame is the latest scan's, so a laser that comes up
        after its first scans is still found; but once it joins the base frame, a scan in
        a frame that does not is a stray one, dropped instead of replacing it."""
        if self.joins_base(self.scan_frame) and not self.joins_base(frame):
            raise _UnknownFrameError(f"scan in {frame!r}, not {self.scan_frame!r}")
        self.scan_frame = frame


class Ros2Source(LiveSource):
    """The team's ROS 2 topics as the server's messages, and the server's decisions back
    as ROS 2 topics."""

    def __init__(
        self,
        nodes: list[Ros2Node],
        namespaces: list[str],
        map_spec: GridSpec,
        *,
        period_s: float,
        lost_after_s: float,
        topics: Ros2Topics | None = None,
        global_tf: bool = False,
        laser_mount: np.ndarray | None = None,
        map_period_s: float = 1.0,
    ) -> None:
        super().__init__(period_s)
        self.nodes = nodes
        self.node = nodes[0]  # the team's topics (map, markers) go out on the first
        self.map_spec = map_spec
        self.topics = topics or Ros2Topics()
        self.lost_after_s = lost_after_s
        self.global_tf = global_tf
        self.map_period_s = map_period_s
        self.laser_mount = laser_mount
        self.clock_origin_s = time.time()
        self._lock = threading.Lock()
        self._robots = [_Robot(i, ns) for i, ns in enumerate(namespaces)]
        self._lost: set[int] = set()
        self._next_map_s = 0.0
        # Per ROS frame: the map last published (a version of one mapper), its publishers.
        self._published_maps: dict[str, MapView] = {}
        self._frame_publishers: dict[str, tuple[Ros2Publisher, Ros2Publisher]] = {}
        self._merges_published = 0
        self._cmd_vel_type = cmd_vel_type(self.node.options.distro, self.topics.cmd_vel_stamped)
        t = self.topics
        self._publishers = []
        for robot, node in zip(self._robots, nodes, strict=True):
            ns = robot.namespace
            subscriptions = (
                (t.odom, "nav_msgs/msg/Odometry", "odom", wire.Qos()),
                (t.scan, "sensor_msgs/msg/LaserScan", "scan", SENSOR_QOS),
                (t.landmarks, "sensor_msgs/msg/PointCloud2", "landmarks", wire.Qos()),
                (t.tf_static, "tf2_msgs/msg/TFMessage", "tf", TF_STATIC_QOS),
                (t.ground_truth, "nav_msgs/msg/Odometry", "truth", wire.Qos()),
            )
            for name, msgtype, kind, qos in subscriptions:
                self._subscribe(node, robot, resolve(ns, name), msgtype, kind, qos)
            tf_topic = "/tf" if global_tf else resolve(ns, t.tf)
            self._publishers.append(
                {
                    "cmd_vel": node.publisher(resolve(ns, t.cmd_vel), self._cmd_vel_type),
                    "tf": node.publisher(tf_topic, "tf2_msgs/msg/TFMessage"),
                    "plan": node.publisher(resolve(ns, t.plan), "nav_msgs/msg/Path"),
                }
            )
        self._merges_tf = self.node.publisher("/tf_static", "tf2_msgs/msg/TFMessage", TF_STATIC_QOS)
        self._map_publishers("map")

    # ------------------------------------------------------------------ callbacks

    def _subscribe(
        self, node: Ros2Node, robot: _Robot, topic: str, msgtype: str, kind: str, qos: wire.Qos
    ) -> None:
        def received(message: object) -> None:
            with self._lock:
                robot.inbox.append((topic, kind, message))
                if kind == "odom":
                    robot.heard_wall_s = time.monotonic()

        node.subscribe(topic, msgtype, received, qos)

    # ------------------------------------------------------------------ start-up

    def ready(self) -> dict[int, np.ndarray]:
        """Robot -> laser mount (its pose in the base frame) of the robots whose odometry,
        scan frame and the static transforms joining them (or the configured
        ``laser_mount``) are known."""
        self._drain()
        mounts = {}
        for robot in self._robots:
            if robot.latest_odometry is not None and robot.scan_frame is not None:
                mount = self.laser_mount
                if mount is None:
                    mount = robot.tf.lookup(robot.base_frame, robot.scan_frame)
                if mount is not None:
                    mounts[robot.index] = mount
        return mounts

    def start(self, mounts: dict[int, np.ndarray]) -> None:
        """Start the run's clock and each ready robot's odometry time line at its latest
        odometry sample (the robots stand still until commands come)."""
        self.clock_origin_s = time.time()
        self._started = time.monotonic()
        for index, mount in mounts.items():
            robot = self._robots[index]
            assert robot.latest_odometry is not None
            robot.pairing = OdometryPairing(index, mount)
            ros_stamp_s, pose = robot.latest_odometry
            robot.pairing.odometry(self._stamp(ros_stamp_s), pose)

    # ------------------------------------------------------------------ DataSource

    def newly_lost(self) -> list[int]:
        now = time.monotonic()
        with self._lock:
            silent = [
                r.index
                for r in self._robots
                if r.pairing is not None
                and r.index not in self._lost
                and now - r.heard_wall_s > self.lost_after_s
            ]
        self._lost.update(silent)
        return silent

    def receive(self) -> list[RobotMessage]:
        """Every robot's decoded messages since the last call, paired with odometry."""
        return self._drain()

    def _drain(self) -> list[RobotMessage]:
        out: list[RobotMessage] = []
        for robot in self._robots:
            with self._lock:
                inbox, robot.inbox = robot.inbox, []
            for topic, kind, message in inbox:
                if robot.index in self._lost:
                    continue
                try:
                    out += self._take(robot, kind, message)
                except _UnknownFrameError as exc:
                    self.nodes[robot.index].drop(topic, "unknown frame", exc)
                except MessageError as exc:
                    self.nodes[robot.index].drop(topic, "invalid message", exc)
        return out

    def deliver(self, snapshot: Snapshot) -> None:
        now_s = time.time()
        frames = self._robot_frames(snapshot)
        for robot, publishers in zip(self._robots, self._publishers, strict=True):
            if robot.index in self._lost or robot.pairing is None:
                continue
            command = snapshot.commands[robot.index] if snapshot.commands else None
            v, omega = (command.v, command.omega) if command is not None else (0.0, 0.0)
            publishers["cmd_vel"].put(self._twist(v, omega, robot, now_s))
            frame = frames[robot.index]
            transform = self._map_to_odom(robot, snapshot.poses[robot.index], frame)
            if transform is not None:
                publishers["tf"].put(transform)
            path = snapshot.paths_m[robot.index]
            if path is not None and path is not robot.last_plan:
                publishers["plan"].put(convert.path_msg(path, now_s, frame, self._distro))
                robot.last_plan = path
        if len(snapshot.merges) > self._merges_published:
            self._publish_merges(snapshot)
        if self.time_s >= self._next_map_s and self._publish_maps(snapshot, now_s):
            self._next_map_s = self.time_s + self.map_period_s

    # ------------------------------------------------------------------ outputs

    def stop(self) -> None:
        """Zero velocity to every robot (the server is going away)."""
        now_s = time.time()
        for _ in range(ZERO_VELOCITY_REPEATS):
            for robot, publishers in zip(self._robots, self._publishers, strict=True):
                publishers["cmd_vel"].put(self._twist(0.0, 0.0, robot, now_s))
            time.sleep(0.05)

    def statistics(self) -> dict:
        """Per robot and topic: messages and bytes per second; latency p50/p95 (ms); what
        was dropped, by reason."""
        stats = TopicStats()
        for node in dict.fromkeys(self.nodes):
            stats.merge(node.statistics())
        elapsed_s = max(self.time_s, 1e-9)
        dropped = Counter(stats.dropped)
        for robot in self._robots:
            if robot.pairing is not None:
                for reason, count in robot.pairing.dropped.items():
                    dropped[f"{resolve(robot.namespace, self.topics.scan)}: {reason}"] += count
        return {
            "elapsed_s": elapsed_s,
            "topics": {
                topic: {"messages": stats.messages[topic], "bytes_per_s": size / elapsed_s}
                for topic, size in sorted(stats.bytes.items())
            },
            "latency": latency_percentiles_ms(stats.latency_s),
            "dropped": dict(dropped),
            "drop_examples": stats.drop_examples,
        }

    def truth(self) -> list[np.ndarray]:
        """Per robot, ``[t, x, y, theta]`` rows of its ``ground_truth`` topic (empty when
        it publishes none, as a real robot)."""
        self._drain()
        return [np.array(r.truth, dtype=float).reshape(-1, 4) for r in self._robots]

    # ------------------------------------------------------------------ internals

    @property
    def _distro(self) -> str:
        return self.node.options.distro

    def _stamp(self, ros_stamp_s: float) -> float:
        return ros_stamp_s - self.clock_origin_s

    def _take(self, robot: _Robot, kind: str, message: object) -> list[RobotMessage]:
        """One decoded ROS message of ``robot`` as server messages (maybe none yet)."""
        if kind == "tf":
            for parent, child, _, pose in convert.tf_transforms(message):
                robot.tf.add(parent, child, pose)
            return []
        if kind == "truth":
            stamp_s, pose, _, _ = convert.odometry_pose(message)
            robot.truth.append((self._stamp(stamp_s), *pose))
            return []
        if kind == "odom":
            stamp_s, pose, frame, child = convert.odometry_pose(message)
            if robot.base_frame is None:
                robot.odom_frame, robot.base_frame = frame, child
            elif (frame, child) != (robot.odom_frame, robot.base_frame):
                raise _UnknownFrameError(
                    f"odometry of {frame} -> {child}, not {robot.odom_frame} -> {robot.base_frame}"
                )
            if robot.pairing is None:
                robot.latest_odometry = (stamp_s, pose)
                return []
            return robot.pairing.odometry(self._stamp(stamp_s), pose)
        if kind == "scan":
            frame = convert.frame_id(message)
            stamp_s = self._stamp(convert.header_stamp_s(message))
            scan = convert.laser_scan(message, robot.index, stamp_s)
            if robot.pairing is None:
                robot.take_scan_frame(frame)
                return []
            if frame != robot.scan_frame:
                raise _UnknownFrameError(f"scan in {frame!r}, not {robot.scan_frame!r}")
            return robot.pairing.scan(scan)
        # landmarks
        if robot.pairing is None:
            return []
        if convert.frame_id(message) != robot.base_frame:
            raise _UnknownFrameError(
                f"landmarks in {convert.frame_id(message)!r}, not {robot.base_frame!r}"
            )
        stamp_s = self._stamp(convert.header_stamp_s(message))
        return robot.pairing.landmarks(convert.landmark_observations(message, robot.index, stamp_s))

    def _twist(self, v: float, omega: float, robot: _Robot, now_s: float) -> object:
        frame = robot.base_frame or "base_link"
        stamped = self._cmd_vel_type.endswith("Stamped")
        return convert.twist_msg(v, omega, self._distro, stamped=stamped, stamp_s=now_s,
                                 frame_id=frame)  # fmt: skip

    def _frame_name(self, base_robot_id: int) -> str:
        """The ROS frame whose origin is robot ``base_robot_id``'s start: ``map`` for
        robot 0's, the team's; ``<ns>/map`` for another robot's (unknown starts)."""
        if base_robot_id == 0:
            return "map"
        return f"{self._robots[base_robot_id].namespace.strip('/')}/map"

    def _robot_frames(self, snapshot: Snapshot) -> list[str]:
        """Per robot, the ROS frame its pose, plan and goal are in."""
        frames = ["map"] * len(self._robots)
        for view in snapshot.frames:
            for robot_id in view.robot_ids:
                frames[robot_id] = self._frame_name(view.robot_ids[0])
        return frames

    def _map_to_odom(
        self, robot: _Robot, laser_in_map: np.ndarray, map_frame: str
    ) -> object | None:
        """``map -> odom`` (``map_frame``: the robot's frame) that puts the base where
        SLAM estimates it: map_T_base * odom_T_base^-1 at the newest odometry the server
        has used."""
        assert robot.pairing is not None
        latest = robot.pairing.latest
        if latest is None:
            return None
        stamp_s, odom_base = latest
        base_in_map = compose(laser_in_map, between(robot.pairing.mount, np.zeros(3)))
        map_to_odom = compose(base_in_map, between(odom_base, np.zeros(3)))
        odom = robot.odom_frame or "odom"
        if self.global_tf and not odom.startswith(robot.namespace.strip("/") + "/"):
            odom = f"{robot.namespace.strip('/')}/{odom}"
        ros_stamp_s = stamp_s + self.clock_origin_s
        return convert.tf_message([(map_frame, odom, ros_stamp_s, map_to_odom)], self._distro)

    def _publish_merges(self, snapshot: Snapshot) -> None:
        """Every merge so far, as ``into -> merged`` frame on ``/tf_static`` (one message
        with all of them: a late subscriber gets only the last)."""
        transforms = [
            (
                self._frame_name(merge.into_robot_ids[0]),
                self._frame_name(merge.merged_robot_ids[0]),
                merge.time_s + self.clock_origin_s,
                merge.decision.pose,
            )
            for merge in snapshot.merges
        ]
        self._merges_tf.put(convert.tf_message(transforms, self._distro))
        self._merges_published = len(snapshot.merges)

    def _publish_maps(self, snapshot: Snapshot, now_s: float) -> bool:
        """The team's map and markers, and with unknown starts each other frame's under
        its first robot's namespace; each only when it changed. Whether any was."""
        if not snapshot.frames:
            return self._publish_map("map", snapshot, self.map_spec, now_s)
        names = [self._frame_name(view.robot_ids[0]) for view in snapshot.frames]
        for gone in set(self._published_maps) - set(names):  # merged: its map is let go
            del self._published_maps[gone]
        published = [
            self._publish_map(name, view.snapshot, view.spec, now_s)
            for name, view in zip(names, snapshot.frames, strict=True)
        ]
        return any(published)

    def _map_publishers(self, frame: str) -> tuple[Ros2Publisher, Ros2Publisher]:
        """The map and markers publishers of a ROS frame: the team's topics for ``map``,
        the same names under the namespace for ``<ns>/map``."""
        if frame not in self._frame_publishers:
            t = self.topics
            map_topic, markers_topic = t.map, t.markers
            if frame != "map":
                namespace = frame.removesuffix("/map")
                map_topic = resolve(namespace, t.map.lstrip("/"))
                markers_topic = resolve(namespace, t.markers.lstrip("/"))
            self._frame_publishers[frame] = (
                self.node.publisher(map_topic, "nav_msgs/msg/OccupancyGrid", MAP_QOS),
                self.node.publisher(markers_topic, "visualization_msgs/msg/MarkerArray"),
            )
        return self._frame_publishers[frame]

    def _publish_map(self, frame: str, snapshot: Snapshot, spec: GridSpec, now_s: float) -> bool:
        """One frame's map and markers, unless this version of its mapper went out
        already (a merge makes a new mapper, whatever its version); whether they went."""
        if self._published_maps.get(frame) == snapshot.map:
            return False
        map_publisher, markers_publisher = self._map_publishers(frame)
        values = snapshot.map.occupancy_values()
        map_publisher.put(convert.known_map_msg(values, spec, now_s, frame, self._distro))
        frontier_xy = spec.cell_to_world(snapshot.frontier_cells)
        targets = [c.target_m for c in snapshot.clusters]
        goals = [g for g in snapshot.goals_m if g is not None]
        markers_publisher.put(
            convert.marker_array_msg(frontier_xy, targets, goals, now_s, frame, self._distro)
        )
        self._published_maps[frame] = snapshot.map
        return True


class _UnknownFrameError(MessageError):
    """A message in a frame the robot's odometry and static transforms do not join."""
