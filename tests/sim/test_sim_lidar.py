"""LiDAR ranges against analytic wall and disc distances, and the noise model."""

from __future__ import annotations

import math

import numpy as np
from simtest_worlds import RES_M, box_world

from acslam.config import LidarConfig
from acslam.grid import GridSpec
from acslam.sim.lidar import LidarSensor, beam_angles, grid_ray_m
from acslam.worlds.vineyard import stamp_discs
from acslam.worlds.world import World

NOISELESS = {"range_noise_std_m": 0.0, "range_noise_rel": 0.0, "angle_noise_std_rad": 0.0}
NO_DISCS = np.zeros((0, 3))


def _box_distance(px: float, py: float, angle: float, x_max: float, y_max: float) -> float:
    """Distance from inside the box [RES_M, x_max] x [RES_M, y_max] to its boundary."""
    c, s = math.cos(angle), math.sin(angle)
    hits = []
    if c > 0:
        hits.append((x_max - px) / c)
    if c < 0:
        hits.append((RES_M - px) / c)
    if s > 0:
        hits.append((y_max - py) / s)
    if s < 0:
        hits.append((RES_M - py) / s)
    return min(hits)


def test_beam_angle_layout() -> None:
    full = beam_angles(LidarConfig(beams=8))
    assert np.allclose(full, -math.pi + np.arange(8) * math.pi / 4)
    narrow = beam_angles(LidarConfig(beams=5, fov_rad=math.pi / 2))
    assert np.allclose(narrow, [-math.pi / 4, -math.pi / 8, 0, math.pi / 8, math.pi / 4])
    assert beam_angles(LidarConfig(beams=1, fov_rad=1.0)).tolist() == [0.0]


def test_ranges_equal_analytic_wall_distances() -> None:
    world = box_world(4.0, 3.0)
    config = LidarConfig(range_max_m=8.0, **NOISELESS)
    sensor = LidarSensor(config, world, np.random.default_rng(0))
    for pose in [(1.3, 1.1, 0.4), (0.5, 2.5, -2.0), (3.71, 0.23, math.pi)]:
        scan = sensor.scan(0, 0.1, pose, NO_DISCS, -1)
        expected = [_box_distance(pose[0], pose[1], pose[2] + a, 3.95, 2.95) for a in scan.angles]
        assert np.allclose(scan.ranges, expected, rtol=0, atol=1e-9)
        assert (scan.angles == sensor.angles_rad).all()


def test_beyond_range_max_is_inf_and_below_range_min_is_invalid() -> None:
    world = box_world(4.0, 3.0)
    config = LidarConfig(range_min_m=0.3, range_max_m=1.0, **NOISELESS)
    scan = LidarSensor(config, world, np.random.default_rng(0)).scan(
        0, 0.0, (0.25, 1.5, 0.0), NO_DISCS, -1
    )
    true = np.array([_box_distance(0.25, 1.5, a, 3.95, 2.95) for a in scan.angles])
    valid = (true >= 0.3) & (true <= 1.0)
    assert np.isinf(scan.ranges[true > 1.0]).all()  # ahead (3.7 m): no return
    assert (scan.ranges[true < 0.3] == 0.0).all()  # behind (0.2 m): invalid reading
    assert (true < 0.3).any() and (true > 1.0).any()
    assert np.allclose(scan.ranges[valid], true[valid], atol=1e-9)
    assert valid.any() and (~valid).any()


def test_other_robot_is_seen_and_own_disc_is_not() -> None:
    world = box_world(6.0, 3.0)
    sensor = LidarSensor(LidarConfig(**NOISELESS), world, np.random.default_rng(0))
    radius = 0.105
    discs = np.array([[1.0, 1.5, radius], [3.0, 1.5, radius]])
    scan = sensor.scan(0, 0.0, (1.0, 1.5, 0.0), discs, 0)
    forward = int(np.argmin(np.abs(scan.angles)))
    assert abs(scan.ranges[forward] - (2.0 - radius)) < 1e-6
    backward = int(np.argmin(np.abs(np.abs(scan.angles) - math.pi)))
    assert abs(scan.ranges[backward] - 0.95) < 1e-9  # the wall, not robot 0's own disc


def test_round_obstacles_are_cast_as_circles_not_their_cells() -> None:
    box = box_world(6.0, 3.0)
    plant = np.array([[3.0, 1.5, 0.2]])
    stamped = box.occupied.copy()
    stamp_discs(stamped, box.spec, plant[:, :2], 0.2)
    world = World("plant", box.spec, stamped, discs=plant, occupied_without_discs=box.occupied)
    sensor = LidarSensor(LidarConfig(**NOISELESS), world, np.random.default_rng(0))
    scan = sensor.scan(0, 0.0, (1.0, 1.52, 0.0), NO_DISCS, -1)
    for k in np.flatnonzero(np.abs(scan.angles) < 0.08):
        a = scan.angles[k]  # exact ray-circle distance from (1.0, 1.52)
        b = -2.0 * math.cos(a) + 0.02 * math.sin(a)
        expected = -b - math.sqrt(b * b - (4.0 + 0.0004 - 0.04))
        assert abs(scan.ranges[k] - expected) < 1e-9
    # Cast against the stamped cells instead, the same beams see a staircase.
    cells = LidarSensor(
        LidarConfig(**NOISELESS), World("cells", box.spec, stamped), np.random.default_rng(0)
    )
    staircase = cells.scan(0, 0.0, (1.0, 1.52, 0.0), NO_DISCS, -1)
    assert np.abs(staircase.ranges - scan.ranges).max() > 0.01


def test_dda_matches_fine_sampling_in_random_grid() -> None:
    rng = np.random.default_rng(5)
    occupied = rng.random((40, 50)) < 0.08
    occupied[18:22, 23:27] = False
    spec = GridSpec(-1.0, 0.5, 0.1, 40, 50)
    world = World("random", spec, occupied)
    px, py = -1.0 + 2.5 + 0.013, 0.5 + 2.0 + 0.037
    samples_m = np.arange(0.0, 6.0, 1e-4)
    for angle in rng.uniform(-math.pi, math.pi, 200):
        c, s = math.cos(angle), math.sin(angle)
        hit = grid_ray_m(world.occupied, -1.0, 0.5, 0.1, px, py, c, s, 5.0)
        cells = spec.world_to_cell(np.stack([px + samples_m * c, py + samples_m * s], axis=1))
        inside = spec.contains(cells)
        blocked = ~inside
        blocked[inside] = occupied[cells[inside, 0], cells[inside, 1]]
        reference = samples_m[np.argmax(blocked)] if blocked.any() else math.inf
        if reference > 5.0:
            assert math.isinf(hit)
        else:
            assert reference - 1e-4 <= hit <= reference + 1e-9


def test_range_noise_matches_model() -> None:
    world = box_world(10.0, 8.0)
    config = LidarConfig(range_noise_std_m=0.01, range_noise_rel=0.02, angle_noise_std_rad=0.0)
    noisy = LidarSensor(config, world, np.random.default_rng(11))
    exact = LidarSensor(LidarConfig(**NOISELESS), world, np.random.default_rng(0))
    pose = (4.1, 3.3, 0.2)
    truth = exact.scan(0, 0.0, pose, NO_DISCS, -1).ranges
    valid = np.isfinite(truth)
    scans = np.array([noisy.scan(0, 0.0, pose, NO_DISCS, -1).ranges for _ in range(100)])
    sigma = config.range_noise_std_m + config.range_noise_rel * truth[valid]
    z = (scans[:, valid] - truth[valid]) / sigma
    assert np.mean(np.abs(z) <= 3.0) >= 0.99
    assert abs(np.std(z) - 1.0) < 0.1
    assert abs(np.mean(z)) < 0.05


def test_angle_noise_moves_the_ray_not_the_reported_angle() -> None:
    world = box_world(10.0, 8.0)
    config = LidarConfig(range_noise_std_m=0.0, range_noise_rel=0.0, angle_noise_std_rad=0.01)
    sensor = LidarSensor(config, world, np.random.default_rng(2))
    pose = (4.1, 3.3, 0.2)
    scan = sensor.scan(0, 0.0, pose, NO_DISCS, -1)
    truth = LidarSensor(LidarConfig(**NOISELESS), world, np.random.default_rng(0)).scan(
        0, 0.0, pose, NO_DISCS, -1
    )
    assert (scan.angles == truth.angles).all()
    diff = np.abs(scan.ranges - truth.ranges)[np.isfinite(truth.ranges)]
    assert diff.max() > 1e-4  # the beams did move
    assert np.median(diff) < 0.1  # by about range * angle error, a few cm at most here
