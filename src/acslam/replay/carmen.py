"""Run SLAM and mapping on a CARMEN laser log (ODOM + FLASER), e.g. Intel Lab or fr079.

The log is replayed in logger-time order through the pieces the simulation server uses:
:class:`SlamBackend` (odometry keyframes in one iSAM2), :class:`LidarConstraints`
(verified sequential and loop-closure ICP factors between keyframes) and
:class:`TeamMap` (the log-odds grid). The state is the *laser* pose: the FLASER line's
``x y theta``. Odometry poses (ODOM lines and the odometry pose of each FLASER line) are
moved to the laser frame by the fixed robot-to-laser offset read off the FLASER lines, and
consecutive poses become :class:`OdometryIncrement` messages, as the simulator's robots
send them; the absolute odometry frame is never used beyond the start pose.

Outputs: ``trajectory.tum`` holds one laser pose per FLASER line, in file order, stamped
with the line's ipc timestamp: its keyframe's optimised pose composed with the odometry
since that keyframe. The map is built once from every scan at its final pose. Deviation
from the simulation server, which moves already integrated scans as SLAM corrects them:
the result is the same grid (TeamMap's fixed-point removal is exact), and integrating once
avoids re-rasterising thousands of scans after each of the log's many loop closures. The
grid's extent is taken from the data (the beam endpoints at the final poses), not fixed.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from acslam.config import MappingConfig, ScanMatchingConfig, SlamConfig
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
from acslam.mapping.occupancy import LogOddsGrid, TeamMap, grid_spec_for_bounds
from acslam.messages import LidarScan, OdometryIncrement
from acslam.slam.backend import SlamBackend
from acslam.slam.lidar_constraints import LidarConstraints
from acslam.trajectory import write_tum
from acslam.worlds.mapio import save_map

CARMEN_SLAM_CONFIG = SlamConfig(
    odom_sigma_xy_per_m=0.1,
    odom_sigma_theta_per_rad=0.1,
    odom_sigma_theta_per_m=0.05,
    keyframe_distance_m=0.5,
    keyframe_angle_rad=0.5,
    isam_relinearize_skip=1,
    isam_factorization="QR",
)
"""Ours: wheel odometry of indoor robots of the era drifts ~5-10 % (the Intel log's heading
notoriously more), so it is weighted well below the laser; keyframes every 0.5 m / 0.5 rad
keep consecutive 180-degree scans overlapping by far more than half. QR factorization,
relinearizing at every update: Cholesky stops on fr079 (see :class:`SlamConfig`)."""

CARMEN_SCAN_MATCHING_CONFIG = ScanMatchingConfig(
    range_noise_std_m=0.01,
    range_noise_rel=0.0,
    angle_noise_std_rad=0.002,
    line_neighbors=5,
    surface_fit="line",
    min_inlier_ratio=0.4,
)
"""A SICK LMS (the laser of the CARMEN-era logs): ~1 cm range noise, no relative term.
Its beams are 0.5-1 deg apart (the simulated LDS-02's 1 deg at 8 m at most), so 5
neighbours already span ~0.5 m at 6 m and more would bend lines round corners; a parabola
through 5 points follows office clutter (on the Intel log it raised the trajectory's RMSE
against the GMapping-corrected log from 0.11 to 0.15 m), so lines are fitted. Cluttered
offices leave many points on no line, so 40 % inliers is asked instead of 60 %."""

CARMEN_MAPPING_CONFIG = MappingConfig(max_range_m=15.0, free_on_no_return=False)
"""Beams are mapped up to 15 m: further, a 0.2 deg heading error moves a hit by more than a
cell, and indoor logs see little beyond. A SICK "no return" (~80 m) is not taken as free
space: indoors it mostly means glass, a dark surface or a grazing angle, and clearing 15 m
along it erases walls behind (the free area outside the Intel lab's walls without this)."""

SUBMAP_KEYFRAMES = 5
"""Sequential matches go against the last 5 keyframes' scans (~2.5 m of way): a 180-degree
laser sees little behind it, and one scan of a cluttered office leaves many points on no
line, so a single-scan reference drifts faster (the simulation server keeps 1)."""

LOOP_SEARCH_PERIOD_S = 2.0
"""Log seconds between loop-closure searches (the server's map-update period plays this role)."""


def laser_offset(log: CarmenLog) -> np.ndarray:
    """The laser pose in the robot frame: the median of ``odom^-1 * laser`` over the scans."""
    offsets = np.array(
        [between(s.odom_pose_xytheta, s.laser_pose_xytheta) for s in log.scans], dtype=float
    )
    return np.median(offsets, axis=0)


def _replay(
    log: CarmenLog,
    slam_config: SlamConfig,
    matching_config: ScanMatchingConfig,
    offset: np.ndarray,
) -> tuple[SlamBackend, LidarConstraints, dict[int, int]]:
    """Feed the records in logger-time order; returns the back end, the scan-matching
    front end and the back end's scan index per FLASER line number."""
    first = min(log.scans, key=lambda s: (s.stamp_s, s.line))
    backend = SlamBackend(slam_config, {0: first.laser_pose_xytheta})
    lidar = LidarConstraints(matching_config, SUBMAP_KEYFRAMES)
    scan_index: dict[int, int] = {}
    previous: np.ndarray | None = None
    previous_stamp = 0.0
    next_loop_search_s = -math.inf
    keyframes = backend.keyframe_count(0)
    for record in log.records:
        if isinstance(record, LaserRecord):
            pose = record.laser_pose_xytheta
        else:
            pose = compose(record.pose_xytheta, offset)
        if previous is not None:
            backend.add_odometry(
                OdometryIncrement(0, record.stamp_s, previous_stamp, *between(previous, pose))
            )
        previous, previous_stamp = pose, record.stamp_s
        if not isinstance(record, LaserRecord):
            continue
        scan = LidarScan(0, record.stamp_s, record.angles_rad, record.ranges_m, NO_RETURN_RANGE_M)
        index = backend.add_scan(scan)
        if index is None:
            continue
        scan_index[record.line] = index
        if backend.keyframe_count(0) == keyframes and len(scan_index) > 1:
            continue
        keyframes = backend.keyframe_count(0)
        lidar.add_scan(backend, index, scan)
        closures = 0
        if record.stamp_s >= next_loop_search_s:
            closures = lidar.close_loops(backend)
            next_loop_search_s = record.stamp_s + LOOP_SEARCH_PERIOD_S
        backend.update(extra_iterations=2 if closures else 0)
    lidar.close_loops(backend)
    backend.update(extra_iterations=5)
    return backend, lidar, scan_index


def _map_spec(scans: list[LaserRecord], poses: list[np.ndarray], config: MappingConfig) -> GridSpec:
    """The smallest grid holding every mapped beam endpoint (and sensor) plus a margin."""
    low = np.full(2, np.inf)
    high = np.full(2, -np.inf)
    for scan, pose in zip(scans, poses, strict=True):
        mapped = np.isfinite(scan.ranges_m) | config.free_on_no_return
        reach = np.minimum(scan.ranges_m[mapped], config.max_range_m)
        angles = scan.angles_rad[mapped] + pose[2]
        x = np.append(pose[0] + reach * np.cos(angles), pose[0])
        y = np.append(pose[1] + reach * np.sin(angles), pose[1])
        low = np.minimum(low, [x.min(), y.min()])
        high = np.maximum(high, [x.max(), y.max()])
    margin = 1.0
    return grid_spec_for_bounds(
        low[0] - margin, low[1] - margin, high[0] + margin, high[1] + margin, config.resolution_m
    )


def _build_map(
    scans: list[LaserRecord], poses: list[np.ndarray], config: MappingConfig
) -> tuple[np.ndarray, GridSpec, float]:
    """Occupancy values of every scan at the given poses, their grid, and the time taken."""
    spec = _map_spec(scans, poses, config)
    start = time.perf_counter()
    team = TeamMap(config, spec=spec)
    for scan, pose in zip(scans, poses, strict=True):
        team.add_scan(0, scan.line, scan.ranges_m, scan.angles_rad, pose)
    return team.global_grid.to_occupancy_values(), spec, time.perf_counter() - start


def _odometry_map(
    scans: list[LaserRecord], config: MappingConfig
) -> tuple[np.ndarray, GridSpec, np.ndarray]:
    poses = [scan.laser_pose_xytheta for scan in scans]
    spec = _map_spec(scans, poses, config)
    grid = LogOddsGrid(spec, config)
    for scan, pose in zip(scans, poses, strict=True):
        grid.integrate(scan.ranges_m, scan.angles_rad, pose)
    return grid.to_occupancy_values(), spec, np.array(poses)


def run_carmen(
    path: str | Path,
    out_dir: str | Path,
    slam_config: SlamConfig = CARMEN_SLAM_CONFIG,
    matching_config: ScanMatchingConfig = CARMEN_SCAN_MATCHING_CONFIG,
    mapping_config: MappingConfig = CARMEN_MAPPING_CONFIG,
    odometry_map: bool = True,
) -> dict:
    """Replay, map and write DIR/trajectory.tum, map.yaml/.pgm/.png,
    odometry_vs_slam.png (unless ``odometry_map`` is False) and metrics.json."""
    out_dir = Path(out_dir)
    wall_start = time.perf_counter()
    log = read_carmen(path)
    if not log.scans:
        raise DataError(path, "no usable FLASER line")
    offset = laser_offset(log)
    slam_start = time.perf_counter()
    backend, lidar, scan_index = _replay(log, slam_config, matching_config, offset)
    slam_s = time.perf_counter() - slam_start

    in_file_order = sorted(log.scans, key=lambda s: s.line)
    used = [scan for scan in in_file_order if scan.line in scan_index]
    poses = [backend.scan_pose(scan_index[scan.line]) for scan in used]
    track = np.array(poses)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_tum(out_dir / "trajectory.tum", np.array([s.ipc_stamp_s for s in used]), track)

    values, spec, mapping_s = _build_map(used, poses, mapping_config)
    save_map(out_dir / "map", values, spec)
    plot_map(out_dir / "map.png", values, spec, track, f"{Path(path).name}: SLAM map")
    if odometry_map:
        odom_values, odom_spec, odom_track = _odometry_map(used, mapping_config)
        plot_map_panels(
            out_dir / "odometry_vs_slam.png",
            [
                (odom_values, odom_spec, odom_track, "odometry only"),
                (values, spec, track, "SLAM (iSAM2 + scan matching)"),
            ],
        )
    wall_s = time.perf_counter() - wall_start

    stamps = np.array([record.stamp_s for record in log.records])
    duration_s = float(stamps[-1] - stamps[0])
    updates_ms = 1e3 * np.array(backend.update_durations_s)
    _, keyframe_poses = backend.trajectory(0)
    metrics = {
        "log": str(path),
        "scans": len(log.scans),
        "scans_used": len(used),
        "odometry_records": len(log.odometry),
        "keyframes": len(keyframe_poses),
        "laser_offset_xytheta": offset.tolist(),
        "trajectory_frame": "laser (FLASER x y theta), one pose per FLASER line in file order",
        "scan_matching": {
            "sequential_accepted": lidar.sequential_added,
            "sequential_rejected": lidar.sequential_rejected,
        },
        "loop_closures": {"accepted": lidar.loops_added, "rejected": lidar.loops_rejected},
        "skipped_lines": {
            "count": len(log.skipped_lines),
            "lines": [number for number, _ in log.skipped_lines],
        },
        "skipped_messages": dict(backend.skipped_messages),
        "log_duration_s": duration_s,
        "wall_time_s": wall_s,
        "real_time_factor": duration_s / wall_s,
        "slam_time_s": slam_s,
        "mapping_time_s": mapping_s,
        "isam2_update_ms": {
            "count": len(updates_ms),
            "mean": float(updates_ms.mean()) if len(updates_ms) else math.nan,
            "p95": float(np.percentile(updates_ms, 95)) if len(updates_ms) else math.nan,
            "max": float(updates_ms.max()) if len(updates_ms) else math.nan,
        },
        "map": {
            "resolution_m": spec.resolution_m,
            "rows": spec.rows,
            "cols": spec.cols,
            "origin_m": [spec.origin_x_m, spec.origin_y_m],
            "occupied_cells": int((values == OCCUPIED).sum()),
            "free_cells": int((values == FREE).sum()),
        },
    }
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics
