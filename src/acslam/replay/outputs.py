"""What every replay of a laser recording writes beside its trajectories: the map of the
kept scans at their final poses, the maps by SLAM and by odometry side by side, and the
metrics every such replay reports.

The map is composed once by the mapper stage from every kept scan at its final pose, on a
grid sized from the data (the beam endpoints at those poses): a recording has no fixed
extent. Composing once gives the grid that following every correction would (the log-odds
mapper removes a scan exactly), without re-placing thousands of scans per loop closure.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig, MappingConfig
from acslam.eval.slam_figures import plot_map, plot_map_panels
from acslam.grid import FREE, OCCUPIED, GridSpec
from acslam.mapping.occupancy import grid_spec_for_bounds
from acslam.messages import LidarScan
from acslam.pipeline.registry import MAPPERS
from acslam.pipeline.stages import Localizer
from acslam.worlds.mapio import save_map

MAP_MARGIN_M = 1.0


@dataclass(frozen=True)
class PosedScans:
    """Scans at the poses a map places them, and each robot's track ((N, 3)) to draw over
    the map."""

    scans: Sequence[LidarScan]
    poses: Sequence[np.ndarray]
    tracks: Sequence[np.ndarray]


@dataclass(frozen=True)
class ReplayMap:
    """The SLAM map's occupancy values on its grid, and the seconds composing it took."""

    values: np.ndarray
    spec: GridSpec
    mapping_time_s: float


def map_spec(
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
    low -= MAP_MARGIN_M
    high += MAP_MARGIN_M
    return grid_spec_for_bounds(low[0], low[1], high[0], high[1], config.resolution_m)


def build_map(posed: PosedScans, algorithms: AlgorithmsConfig) -> tuple[np.ndarray, GridSpec]:
    """Occupancy values of the scans at their poses by the mapper stage ``algorithms``
    names, on a grid sized from the data."""
    spec = map_spec(posed.scans, posed.poses, algorithms.mapper)
    mapper = MAPPERS.create(algorithms.mapper, spec=spec)
    for index, (scan, pose) in enumerate(zip(posed.scans, posed.poses, strict=True)):
        mapper.add_scan(scan.robot_id, index, scan.ranges, scan.angles, pose, scan.range_max_m)
    return mapper.occupancy_values(), spec


def write_maps(
    out_dir: Path,
    title: str,
    slam: PosedScans,
    odometry: PosedScans | None,
    algorithms: AlgorithmsConfig,
) -> ReplayMap:
    """DIR/map.yaml/.pgm and map.png of the SLAM map; with ``odometry``,
    odometry_vs_slam.png: the same scans mapped at their odometry poses beside it."""
    started = time.perf_counter()
    values, spec = build_map(slam, algorithms)
    mapping_time_s = time.perf_counter() - started
    save_map(out_dir / "map", values, spec)
    plot_map(out_dir / "map.png", values, spec, slam.tracks, f"{title}: SLAM map")
    if odometry is not None:
        odom_values, odom_spec = build_map(odometry, algorithms)
        plot_map_panels(
            out_dir / "odometry_vs_slam.png",
            [
                (odom_values, odom_spec, odometry.tracks, "odometry only"),
                (values, spec, slam.tracks, "SLAM (iSAM2 + scan matching)"),
            ],
        )
    return ReplayMap(values, spec, mapping_time_s)


def replay_metrics(
    localizer: Localizer, replay_map: ReplayMap, duration_s: float, timings_s: dict[str, float]
) -> dict:
    """The metrics every laser replay reports: matching and loop-closure counts, skipped
    messages, timings (``wall_time_s`` among them), each robot's odometry calibration and
    the map's size."""
    diagnostics = localizer.diagnostics()
    values, spec = replay_map.values, replay_map.spec
    return {
        "scan_matching": diagnostics["scan_matching"],
        "loop_closures": diagnostics["loop_closures"],
        "skipped_messages": diagnostics["skipped_messages"],
        "log_duration_s": duration_s,
        **timings_s,
        "mapping_time_s": replay_map.mapping_time_s,
        "real_time_factor": duration_s / timings_s["wall_time_s"],
        "isam2_update_ms": diagnostics["isam2_update_ms"],
        "odometry_calibration": diagnostics["odometry_calibration"],
        "map": {
            "resolution_m": spec.resolution_m,
            "rows": spec.rows,
            "cols": spec.cols,
            "origin_m": [spec.origin_x_m, spec.origin_y_m],
            "occupied_cells": int((values == OCCUPIED).sum()),
            "free_cells": int((values == FREE).sum()),
        },
    }
