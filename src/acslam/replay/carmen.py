"""Run SLAM and mapping on a CARMEN laser log (ODOM + FLASER), e.g. Intel Lab or fr079.

The log plays as the ROS 2 bag ``acslam convert carmen`` writes of it
(:func:`acslam.ros2.carmen_bag.write_carmen`), held in memory, through the replay of
``acslam slam rosbag`` (:func:`acslam.replay.rosbag.replay_bag`) with the ``carmen`` preset
of algorithms (``presets/carmen.yaml``). There is one way from a log to the localizer,
so the two commands give the same trajectory: ranges and beam angles at float32 (the
LaserScan's precision, far below the log's 1 cm resolution), headings through a
quaternion, stamps in ROS time's nanoseconds, the laser mount through ``tf_static``, and
each FLASER line's scan at its own laser pose, where the odometry increments up to it
have brought the robot's laser frame. The state is the *laser* pose; the start pose the
laser pose of the first record (where the increments begin).

Outputs: ``trajectory.tum`` holds one laser pose per FLASER line the localizer kept, in
file order, stamped with the line's ipc timestamp: its keyframe's optimised pose composed
with the odometry since that keyframe. The map and figures are those of every laser replay
(:mod:`acslam.replay.outputs`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig
from acslam.datasets.carmen import LaserRecord, read_carmen
from acslam.provenance import write_metrics
from acslam.replay import preset
from acslam.replay.outputs import PosedScans, replay_metrics, write_maps
from acslam.replay.rosbag import replay_bag
from acslam.ros2.bag import MemoryBag
from acslam.ros2.carmen_bag import write_carmen
from acslam.trajectory import write_tum


def run_carmen(
    path: str | Path,
    out_dir: str | Path,
    *,
    algorithms: AlgorithmsConfig | None = None,
    odometry_map: bool = True,
) -> dict:
    """Replay with ``algorithms`` (default: the ``carmen`` preset), map and write
    DIR/trajectory.tum, map.yaml/.pgm/.png, odometry_vs_slam.png (unless
    ``odometry_map`` is False) and metrics.json."""
    algorithms = algorithms or preset("carmen")
    out_dir = Path(out_dir)
    wall_start = time.perf_counter()
    log = read_carmen(path)
    bag = MemoryBag(path)
    write_carmen(log, bag)
    replay = replay_bag(bag, algorithms=algorithms)
    localizer = replay.replayed.localizer
    (stream,) = replay.streams

    # The bag's scans are the FLASER records in time order, each paired as it is (the
    # odometry has a sample at every scan's stamp).
    records = [record for record in log.records if isinstance(record, LaserRecord)]
    record_of = {id(scan): record for scan, record in zip(stream.robot.scans, records, strict=True)}
    used = sorted(
        ((record_of[id(scan.received)], scan) for scan in replay.replayed.scans),
        key=lambda pair: pair[0].line,
    )
    poses = [localizer.scan_pose(scan.index) for _, scan in used]
    track = np.array(poses)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_tum(out_dir / "trajectory.tum", np.array([r.ipc_stamp_s for r, _ in used]), track)

    odometry = None
    if odometry_map:
        odometry_poses = [record.laser_pose_xytheta for record, _ in used]
        odometry = PosedScans(
            [scan.received for _, scan in used], odometry_poses, [np.array(odometry_poses)]
        )
    slam = PosedScans([scan.mappable for _, scan in used], poses, [track])
    replay_map = write_maps(out_dir, Path(path).name, slam, odometry, algorithms)
    timings_s = {
        "wall_time_s": time.perf_counter() - wall_start,
        "slam_time_s": replay.slam_time_s,
    }
    _, keyframe_poses = localizer.trajectory(stream.robot.index)
    metrics = {
        "log": str(path),
        "scans": len(log.scans),
        "scans_used": len(used),
        "odometry_records": len(log.odometry),
        "keyframes": len(keyframe_poses),
        "laser_offset_xytheta": stream.mount.tolist(),
        "trajectory_frame": "laser (FLASER x y theta), one pose per FLASER line in file order",
        "skipped_lines": {
            "count": len(log.skipped_lines),
            "lines": [number for number, _ in log.skipped_lines],
        },
        **replay_metrics(localizer, replay_map, replay.duration_s, timings_s),
    }
    return write_metrics(out_dir, metrics)
