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
with the odometry since that keyframe. The map is composed once by the mapper stage from
every kept scan at its final pose, on a grid sized from the data (the beam endpoints at
the final poses): a recording has no fixed extent.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig, MappingConfig
from acslam.datasets.carmen import (
    NO_RETURN_RANGE_M,
    CarmenLog,
    LaserRecord,
    read_carmen,
)
from acslam.errors import DataError
from acslam.eval.slam_figures import plot_map, plot_map_panels
from acslam.geometry import between, compose
from acslam.grid import FREE, OCCUPIED, GridSpec
from acslam.mapping.occupancy import grid_spec_for_bounds
from acslam.messages import LidarScan, OdometryIncrement, RobotMessage
from acslam.pipeline.registry import MAPPERS
from acslam.pipeline.stages import Localizer
from acslam.replay import localize, preset
from acslam.trajectory import write_tum
from acslam.worlds.mapio import save_map


def laser_offset(log: CarmenLog) -> np.ndarray:
    """The laser pose in the robot frame: the median of ``odom^-1 * laser`` over the scans."""
    offsets = np.array(
        [between(s.odom_pose_xytheta, s.laser_pose_xytheta) for s in log.scans], dtype=float
    )
    return np.median(offsets, axis=0)


def carmen_messages(log: CarmenLog, offset: np.ndarray) -> list[RobotMessage]:
    """The log as robot 0's messages, in logger-time order: the laser pose's odometry
    increment up to every record, and each FLASER scan."""
    messages: list[RobotMessage] = []
    previous: np.ndarray | None = None
    previous_stamp = 0.0
    for record in log.records:
        if isinstance(record, LaserRecord):
            pose = record.laser_pose_xytheta
        else:
            pose = compose(record.pose_xytheta, offset)
        if previous is not None:
            increment = between(previous, pose)
            messages.append(OdometryIncrement(0, record.stamp_s, previous_stamp, *increment))
        previous, previous_stamp = pose, record.stamp_s
        if isinstance(record, LaserRecord):
            messages.append(
                LidarScan(0, record.stamp_s, record.angles_rad, record.ranges_m, NO_RETURN_RANGE_M)
            )
    return messages


def _map_spec(
    scans: Sequence[LidarScan], poses: Sequence[np.ndarray], config: MappingConfig
) -> GridSpec:
    """The smallest grid holding every mapped beam endpoint (and sensor) plus a margin."""
    low = np.full(2, np.inf)
    high = np.full(2, -np.inf)
    for scan, pose in zip(scans, poses, strict=True):
        mapped = np.isfinite(scan.ranges) | config.free_on_no_return
        reach = np.minimum(scan.ranges[mapped], config.max_range_m)
        angles = scan.angles[mapped] + pose[2]
        x = np.append(pose[0] + reach * np.cos(angles), pose[0])
        y = np.append(pose[1] + reach * np.sin(angles), pose[1])
        low = np.minimum(low, [x.min(), y.min()])
        high = np.maximum(high, [x.max(), y.max()])
    margin = 1.0
    return grid_spec_for_bounds(
        low[0] - margin, low[1] - margin, high[0] + margin, high[1] + margin, config.resolution_m
    )


def _build_map(
    scans: Sequence[LidarScan], poses: Sequence[np.ndarray], algorithms: AlgorithmsConfig
) -> tuple[np.ndarray, GridSpec]:
    """Occupancy values of the scans at the given poses by the mapper stage, on a grid
    sized from the data (a recording has no fixed extent). Composing once at the final
    poses gives the grid that following every correction would (the log-odds mapper
    removes a scan exactly), without re-placing thousands of scans per loop closure."""
    spec = _map_spec(scans, poses, algorithms.mapper)
    mapper = MAPPERS.create(algorithms.mapper, spec=spec)
    for index, (scan, pose) in enumerate(zip(scans, poses, strict=True)):
        mapper.add_scan(scan.robot_id, index, scan.ranges, scan.angles, pose, scan.range_max_m)
    return mapper.occupancy_values(), spec


def _metrics(
    path: str | Path,
    log: CarmenLog,
    offset: np.ndarray,
    scans_used: int,
    localizer: Localizer,
    values: np.ndarray,
    spec: GridSpec,
    timings_s: dict[str, float],
) -> dict:
    stamps = np.array([record.stamp_s for record in log.records])
    duration_s = float(stamps[-1] - stamps[0])
    diagnostics = localizer.diagnostics()
    _, keyframe_poses = localizer.trajectory(0)
    return {
        "log": str(path),
        "scans": len(log.scans),
        "scans_used": scans_used,
        "odometry_records": len(log.odometry),
        "keyframes": len(keyframe_poses),
        "laser_offset_xytheta": offset.tolist(),
        "trajectory_frame": "laser (FLASER x y theta), one pose per FLASER line in file order",
        "scan_matching": diagnostics["scan_matching"],
        "loop_closures": diagnostics["loop_closures"],
        "skipped_lines": {
            "count": len(log.skipped_lines),
            "lines": [number for number, _ in log.skipped_lines],
        },
        "skipped_messages": diagnostics["skipped_messages"],
        "log_duration_s": duration_s,
        **timings_s,
        "real_time_factor": duration_s / timings_s["wall_time_s"],
        "isam2_update_ms": diagnostics["isam2_update_ms"],
        "map": {
            "resolution_m": spec.resolution_m,
            "rows": spec.rows,
            "cols": spec.cols,
            "origin_m": [spec.origin_x_m, spec.origin_y_m],
            "occupied_cells": int((values == OCCUPIED).sum()),
            "free_cells": int((values == FREE).sum()),
        },
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
    # The increments begin at the first record (an ODOM line may come before any FLASER
    # line), so the estimate starts at that record's laser pose.
    first = log.records[0]
    start = (
        first.laser_pose_xytheta
        if isinstance(first, LaserRecord)
        else compose(first.pose_xytheta, offset)
    )
    slam_start = time.perf_counter()
    result = localize(messages, algorithms, {0: start}, start_s=first.stamp_s)
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

    mapping_start = time.perf_counter()
    values, spec = _build_map([scan.mappable for _, scan in used], poses, algorithms)
    mapping_s = time.perf_counter() - mapping_start
    save_map(out_dir / "map", values, spec)
    plot_map(out_dir / "map.png", values, spec, track, f"{Path(path).name}: SLAM map")
    if odometry_map:
        odometry_poses = [record.laser_pose_xytheta for record, _ in used]
        odom_values, odom_spec = _build_map(
            [scan.received for _, scan in used], odometry_poses, algorithms
        )
        plot_map_panels(
            out_dir / "odometry_vs_slam.png",
            [
                (odom_values, odom_spec, np.array(odometry_poses), "odometry only"),
                (values, spec, track, "SLAM (iSAM2 + scan matching)"),
            ],
        )
    wall_s = time.perf_counter() - wall_start

    timings_s = {"wall_time_s": wall_s, "slam_time_s": slam_s, "mapping_time_s": mapping_s}
    metrics = _metrics(path, log, offset, len(used), localizer, values, spec, timings_s)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics
