"""Scan matching speed: point-to-line ICP of two 360-beam scans in a simulated room.

Goal: <= 5 ms per match (10 Hz LiDAR, several robots and loop-closure checks per cycle).
Times are also printed as a ratio to building a cKDTree of one scan's points, measured in
the same process, so figures compare across machines.

Run: ``python benchmarks/scan_matching_speed.py``
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree
from timing import median_ms

from acslam.config import LidarConfig, ScanMatchingConfig
from acslam.geometry import between, compose
from acslam.grid import GridSpec
from acslam.mapping.scan_matching import match_scans, prepare_scan
from acslam.sim.lidar import LidarSensor
from acslam.worlds.world import World


def room_world() -> World:
    """An 8 m x 6 m room with four boxes, 0.05 m cells."""
    occupied = np.zeros((122, 162), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    for row, col, height, width in (
        (20, 30, 10, 14),
        (80, 40, 8, 8),
        (50, 110, 15, 6),
        (95, 120, 6, 20),
    ):
        occupied[row : row + height, col : col + width] = True
    return World("room", GridSpec(0.0, 0.0, 0.05, 122, 162), occupied)


def main() -> None:
    config = ScanMatchingConfig()
    sensor = LidarSensor(LidarConfig(), room_world(), np.random.default_rng(0))
    pose_a = np.array([4.0, 3.5, 0.3])
    pose_b = compose(pose_a, np.array([0.3, -0.2, 0.15]))
    no_discs = np.zeros((0, 3))
    scan_a, scan_b = (sensor.scan(0, 0.0, tuple(pose), no_discs, -1) for pose in (pose_a, pose_b))
    reference = prepare_scan(scan_a.angles, scan_a.ranges, config)
    query = prepare_scan(scan_b.angles, scan_b.ranges, config)
    truth = between(pose_a, pose_b)
    guess = truth + np.array([0.05, -0.05, 0.03])

    tree_ms = median_ms(lambda: cKDTree(reference.points_m), 300)
    prepare_ms = median_ms(lambda: prepare_scan(scan_b.angles, scan_b.ranges, config), 300)
    match_ms = median_ms(lambda: match_scans(reference, query, guess, config), 300)
    total_ms = median_ms(
        lambda: match_scans(
            prepare_scan(scan_a.angles, scan_a.ranges, config),
            prepare_scan(scan_b.angles, scan_b.ranges, config),
            guess,
            config,
        ),
        300,
    )
    result = match_scans(reference, query, guess, config)
    error = result.relative - truth
    print(
        f"360-beam scans, {len(reference.points_m)} / {len(query.points_m)} returns; "
        f"{result.iterations} iterations, converged={result.converged}, error "
        f"{1e3 * math.hypot(error[0], error[1]):.2f} mm / {1e3 * error[2]:.2f} mrad"
    )
    print(f"reference: cKDTree build of {len(reference.points_m)} points: {tree_ms:.3f} ms")
    rows = [
        ("prepare_scan (tree + lines)", prepare_ms, None),
        ("match_scans (prepared scans)", match_ms, 5.0),
        ("prepare both + match", total_ms, 5.0),
    ]
    for name, ms, goal in rows:
        verdict = (
            "" if goal is None else f"  goal <= {goal:g} ms: {'met' if ms <= goal else 'MISSED'}"
        )
        print(f"{name:30s} {ms:8.3f} ms = {ms / tree_ms:7.1f} x cKDTree build{verdict}")


if __name__ == "__main__":
    main()
