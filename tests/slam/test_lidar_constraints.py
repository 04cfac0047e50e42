"""Sequential LiDAR constraints: the previous keyframe and a longer baseline."""

from __future__ import annotations

import numpy as np

from acslam.config import LidarConfig, ScanMatchingConfig, SlamConfig
from acslam.grid import GridSpec
from acslam.messages import OdometryIncrement
from acslam.sim.lidar import LidarSensor
from acslam.slam.backend import SlamBackend
from acslam.slam.lidar_constraints import LidarConstraints
from acslam.worlds.world import World

STEP_M = 0.1


def _drive(baseline_m: float) -> list[tuple[int, int]]:
    """Drive 3 m along a 6 m x 3 m box, a scan and an odometry step every 0.1 m; returns
    the keyframe pairs of the verified sequential constraints."""
    occupied = np.zeros((60, 120), dtype=bool)  # 6 m x 3 m at 5 cm, walls all round
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    world = World("box", GridSpec(0.0, 0.0, 0.05, 60, 120), occupied)
    sensor = LidarSensor(LidarConfig(), world, np.random.default_rng(3))
    slam = SlamBackend(SlamConfig(keyframe_distance_m=0.3), {0: np.array([1.0, 1.5, 0.0])})
    lidar = LidarConstraints(ScanMatchingConfig(sequential_baseline_m=baseline_m))
    pairs = []
    add = slam.scans.add_constraint

    def record(index_a, index_b, *args) -> None:
        pairs.append((slam.scans.keyframe(index_a)[1], slam.scans.keyframe(index_b)[1]))
        add(index_a, index_b, *args)

    slam.scans.add_constraint = record
    for k in range(31):
        if k:
            slam.add_odometry(OdometryIncrement(0, k * 0.5, (k - 1) * 0.5, STEP_M, 0.0, 0.0))
        scan = sensor.scan(0, k * 0.5, (1.0 + k * STEP_M, 1.5, 0.0), np.zeros((0, 3)), -1)
        index = slam.add_scan(scan)
        if index is not None:
            lidar.add_scan(slam, index, scan)
        slam.update()
    return pairs


def test_each_keyframe_is_also_matched_to_the_latest_one_a_baseline_back() -> None:
    pairs = _drive(baseline_m=1.0)
    keyframes = max(b for _, b in pairs)
    assert keyframes == 10  # 3 m at 0.3 m per keyframe
    previous = {(k - 1, k) for k in range(1, keyframes + 1)}
    # Keyframes 0.3 m apart: the latest at least 1 m back is 4 keyframes back.
    baseline = {(k - 4, k) for k in range(4, keyframes + 1)}
    assert set(pairs) == previous | baseline
    assert set(_drive(baseline_m=0.0)) == previous
