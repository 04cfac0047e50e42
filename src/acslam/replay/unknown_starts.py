"""A team's bag replayed without known relative starts: each robot in its own frame, then
the robots' maps merged.

Nothing in a bag need say where the robots started relative to each other: each robot's
odometry starts in its own frame. So each robot is replayed through SLAM alone, starting
at the origin of its own frame, and mapped alone. Then the maps are merged
(:func:`acslam.mapping.merge.find_merge`: a global search of every pose, accepted only
when verified): the first robot's frame is the reference, and a robot's map that merges
into the reference map brings its scans, at their poses carried into the reference frame,
into that map; the grown map is then tried against the robots not merged yet, until no
more merge is accepted. A wrong merge is worse than none, so a robot that does not merge
keeps its own frame, map and trajectory, and the metrics say why.

The merge is rigid: each robot's trajectory is its own SLAM's, carried whole into the
reference frame (no joint optimization across robots after the merge).

Outputs: the reference map with every merged robot (``map.yaml``/``.pgm``/``.png``),
``merge_<robot>.png`` per merged robot (the map before, the robot's own map, the map
after), ``map_<robot>.yaml`` for a robot that did not merge, one TUM trajectory of the
base per robot (in the reference frame if merged, else in its own), and metrics.json.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig
from acslam.eval.slam_figures import plot_map, plot_map_panels
from acslam.geometry import between, compose, wrap_angle
from acslam.grid import GridSpec
from acslam.mapping.merge import MergeDecision, find_merge
from acslam.messages import LidarScan
from acslam.provenance import write_metrics
from acslam.replay.outputs import PosedScans, build_map
from acslam.replay.rosbag import BagReplay, replay_bag, robot_metrics, trajectory_name
from acslam.ros2.bag import BagReader
from acslam.ros2.source import Ros2Topics
from acslam.trajectory import write_tum
from acslam.worlds.mapio import save_map


@dataclass
class _Robot:
    """One robot replayed alone: its replay, its scans at their poses in its own frame,
    and, once merged, its frame's pose in the reference frame."""

    name: str
    replay: BagReplay
    scans: list[LidarScan]
    poses: list[np.ndarray]
    frame_in_reference: np.ndarray | None = None
    decision: MergeDecision | None = None

    def posed(self, frame: np.ndarray) -> tuple[list[LidarScan], list[np.ndarray]]:
        return self.scans, [compose(frame, pose) for pose in self.poses]


def _replay_alone(
    bag: BagReader, namespace: str, index: int, topics: Ros2Topics,
    algorithms: AlgorithmsConfig, finish: bool,
) -> _Robot:  # fmt: skip
    replay = replay_bag(
        bag, namespaces=(namespace,), topics=topics, algorithms=algorithms, finish=finish,
        own_frames=True,
    )  # fmt: skip
    kept, localizer = replay.replayed.scans, replay.replayed.localizer
    # Each replay numbers its one robot 0; the team map needs them apart.
    scans = [replace(scan.mappable, robot_id=index) for scan in kept]
    poses = [localizer.scan_pose(scan.index) for scan in kept]
    return _Robot(replay.streams[0].robot.name, replay, scans, poses)


def _team_map(
    robots: Sequence[_Robot], algorithms: AlgorithmsConfig
) -> tuple[np.ndarray, GridSpec, list[np.ndarray]]:
    """The map of the robots' scans in the reference frame, and their laser tracks."""
    scans, poses, tracks = [], [], []
    for robot in robots:
        assert robot.frame_in_reference is not None
        robot_scans, robot_poses = robot.posed(robot.frame_in_reference)
        scans += robot_scans
        poses += robot_poses
        tracks.append(np.array(robot_poses).reshape(-1, 3))
    values, spec = build_map(PosedScans(scans, poses, tracks), algorithms)
    return values, spec, tracks


def _merge_all(
    robots: list[_Robot], algorithms: AlgorithmsConfig, out_dir: Path
) -> tuple[np.ndarray, GridSpec, list[np.ndarray]]:
    """Merge robots into the first one's frame while any merge is accepted; writes a
    figure per merge."""
    robots[0].frame_in_reference = np.zeros(3)
    merged = [robots[0]]
    values, spec, tracks = _team_map(merged, algorithms)
    own = {}
    for robot in robots[1:]:
        own_values, own_spec = build_map(
            PosedScans(robot.scans, robot.poses, [np.array(robot.poses).reshape(-1, 3)]),
            algorithms,
        )
        own[robot.name] = (own_values, own_spec)
    progress = True
    while progress:
        progress = False
        for robot in robots:
            if robot.frame_in_reference is not None:
                continue
            decision = find_merge(values, spec, *own[robot.name])
            robot.decision = decision
            if not decision.accepted:
                continue
            assert decision.pose is not None
            robot.frame_in_reference = decision.pose
            merged.append(robot)
            before = (values, spec, tracks, "before: " + ", ".join(r.name for r in merged[:-1]))
            values, spec, tracks = _team_map(merged, algorithms)
            plot_map_panels(
                out_dir / f"merge_{robot.name.replace('/', '_')}.png",
                [
                    before,
                    (
                        *own[robot.name],
                        [np.array(robot.poses).reshape(-1, 3)],
                        f"{robot.name}, its own frame",
                    ),
                    (values, spec, tracks, f"after: {robot.name} merged"),
                ],
            )
            progress = True
    for robot in robots:
        if robot.frame_in_reference is None:
            stem = out_dir / f"map_{robot.name.replace('/', '_')}"
            save_map(stem, *own[robot.name])
    return values, spec, tracks


def _odometry_error(robots: Sequence[_Robot], robot: _Robot) -> dict | None:
    """The merged frame against the relative start the bag's odometry gives (exact for a
    bag of `acslam run --record`, whose robots' odometry starts at their true starts)."""
    if robot.frame_in_reference is None:
        return None
    reference = robots[0].replay.streams[0].odometry_start
    expected = between(reference, robot.replay.streams[0].odometry_start)
    found = robot.frame_in_reference
    return {
        "translation_m": float(np.linalg.norm(found[:2] - expected[:2])),
        "rotation_rad": abs(wrap_angle(float(found[2] - expected[2]))),
    }


def run_rosbag_unknown_starts(
    path: Path,
    out_dir: Path,
    *,
    namespaces: Sequence[str],
    topics: Ros2Topics,
    algorithms: AlgorithmsConfig | None,
    finish: bool,
) -> dict:
    """Replay each robot of the bag alone in its own frame, merge the maps, and write the
    outputs of the module docstring (``algorithms``: default the simulated robots')."""
    algorithms = algorithms or AlgorithmsConfig()
    path, out_dir = Path(path), Path(out_dir)
    wall_start = time.perf_counter()
    with BagReader(path) as bag:
        robots = [
            _replay_alone(bag, namespace, index, topics, algorithms, finish)
            for index, namespace in enumerate(namespaces)
        ]
    slam_time_s = sum(robot.replay.slam_time_s for robot in robots)
    merge_start = time.perf_counter()
    values, spec, tracks = _merge_all(robots, algorithms, out_dir)
    merge_time_s = time.perf_counter() - merge_start
    save_map(out_dir / "map", values, spec)
    merged_names = [r.name for r in robots if r.frame_in_reference is not None]
    plot_map(out_dir / "map.png", values, spec, tracks, f"{path.name}: {', '.join(merged_names)}")
    for robot in robots:
        stream = robot.replay.streams[0]
        frame = robot.frame_in_reference if robot.frame_in_reference is not None else np.zeros(3)
        inverse_mount = between(stream.mount, np.zeros(3))
        kept = robot.replay.replayed.scans
        stamps = np.array([scan.received.stamp for scan in kept])
        _, laser = robot.posed(frame)
        base = np.array([compose(pose, inverse_mount) for pose in laser]).reshape(-1, 3)
        write_tum(out_dir / trajectory_name(stream.robot.namespace), stamps, base)
    metrics = {
        "bag": str(path),
        "relative_starts": "unknown",
        "reference_frame": f"{robots[0].name}'s start",
        "robots": {
            robot.name: {
                **robot_metrics(robot.replay.streams[0], robot.replay.replayed.scans,
                                robot.replay.replayed.localizer),
                "loop_closures": robot.replay.replayed.localizer.diagnostics()["loop_closures"],
                "merged": robot.frame_in_reference is not None,
                "merge": None if robot.decision is None else robot.decision.as_dict(),
                "merge_error_vs_odometry": _odometry_error(robots, robot),
            }
            for robot in robots
        },
        "trajectory_frame": "base, in the reference frame if merged, else in the robot's own",
        "finished": finish,
        "log_duration_s": max(robot.replay.duration_s for robot in robots),
        "wall_time_s": time.perf_counter() - wall_start,
        "slam_time_s": slam_time_s,
        "merge_time_s": merge_time_s,
        "map": {
            "resolution_m": spec.resolution_m,
            "rows": spec.rows,
            "cols": spec.cols,
            "origin_m": [spec.origin_x_m, spec.origin_y_m],
        },
    }  # fmt: skip
    return write_metrics(out_dir, metrics)
