"""Run SLAM and mapping on a CARMEN laser log (ODOM + FLASER), e.g. Intel Lab or fr079.

The log becomes robot 0's messages and plays through the localizer stage of ``acslam
run`` (:func:`acslam.replay.localize`) with the ``carmen`` preset of algorithms
(``presets/carmen.yaml``). The state is the *laser* pose: the FLASER line's ``x y theta``.
Odometry poses (ODOM lines and the odometry pose of each FLASER line) are moved to the
laser frame by the fixed robot-to-laser offset read off the FLASER lines, and consecutive
poses become :class:`OdometryIncrement` messages, as the simulator's robots send them; the
absolute odometry frame is never used beyond the start pose, the laser pose of the first
record (where the increments begin).

Outputs: ``trajectory.tum`` holds one laser pose per FLASER line the localizer kept, in
file order, stamped with the line's ipc timestamp: its keyframe's optimised pose composed
with the odometry since that keyframe. The map and figures are those of every laser replay
(:mod:`acslam.replay.outputs`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig
from acslam.datasets.carmen import (
    NO_RETURN_RANGE_M,
    CarmenLog,
    LaserRecord,
    OdometryRecord,
    laser_offset,
    read_carmen,
)
from acslam.errors import DataError
from acslam.geometry import between, compose
from acslam.messages import LidarScan, OdometryIncrement, RobotMessage
from acslam.pipeline.stages import Localizer
from acslam.replay import localize, preset
from acslam.replay.outputs import PosedScans, ReplayMap, replay_metrics, write_maps
from acslam.trajectory import write_tum


def laser_pose(record: OdometryRecord | LaserRecord, offset: np.ndarray) -> np.ndarray:
    """The laser pose a record gives: a FLASER line's own, an ODOM pose moved by ``offset``."""
    if isinstance(record, LaserRecord):
        return record.laser_pose_xytheta
    return compose(record.pose_xytheta, offset)


def carmen_messages(log: CarmenLog, offset: np.ndarray) -> list[RobotMessage]:
    """The log as robot 0's messages, in logger-time order: the laser pose's odometry
    increment up to every record, and each FLASER scan."""
    messages: list[RobotMessage] = []
    previous: np.ndarray | None = None
    previous_stamp = 0.0
    for record in log.records:
        pose = laser_pose(record, offset)
        if previous is not None:
            increment = between(previous, pose)
            messages.append(OdometryIncrement(0, record.stamp_s, previous_stamp, *increment))
        previous, previous_stamp = pose, record.stamp_s
        if isinstance(record, LaserRecord):
            messages.append(
                LidarScan(0, record.stamp_s, record.angles_rad, record.ranges_m, NO_RETURN_RANGE_M)
            )
    return messages


def _metrics(
    path: str | Path,
    log: CarmenLog,
    offset: np.ndarray,
    scans_used: int,
    localizer: Localizer,
    replay_map: ReplayMap,
    timings_s: dict[str, float],
) -> dict:
    stamps = np.array([record.stamp_s for record in log.records])
    _, keyframe_poses = localizer.trajectory(0)
    return {
        "log": str(path),
        "scans": len(log.scans),
        "scans_used": scans_used,
        "odometry_records": len(log.odometry),
        "keyframes": len(keyframe_poses),
        "laser_offset_xytheta": offset.tolist(),
        "trajectory_frame": "laser (FLASER x y theta), one pose per FLASER line in file order",
        "skipped_lines": {
            "count": len(log.skipped_lines),
            "lines": [number for number, _ in log.skipped_lines],
        },
        **replay_metrics(localizer, replay_map, float(stamps[-1] - stamps[0]), timings_s),
    }


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
    if not log.scans:
        raise DataError(path, "no usable FLASER line")
    offset = laser_offset(log)
    messages = carmen_messages(log, offset)
    first = log.records[0]
    slam_start = time.perf_counter()
    result = localize(messages, algorithms, {0: laser_pose(first, offset)}, start_s=first.stamp_s)
    slam_s = time.perf_counter() - slam_start
    localizer = result.localizer

    kept = {id(scan.received): scan for scan in result.scans}
    records = [r for r in log.records if isinstance(r, LaserRecord)]
    scans = [m for m in messages if isinstance(m, LidarScan)]
    used = sorted(
        ((record, kept[id(scan)]) for record, scan in zip(records, scans, strict=True)
         if id(scan) in kept),
        key=lambda pair: pair[0].line,
    )  # fmt: skip
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
    timings_s = {"wall_time_s": time.perf_counter() - wall_start, "slam_time_s": slam_s}
    metrics = _metrics(path, log, offset, len(used), localizer, replay_map, timings_s)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics
