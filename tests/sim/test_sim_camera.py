"""Landmark camera visibility, occlusion, exact geometry and noise."""

from __future__ import annotations

import math

import numpy as np
from simtest_worlds import box_world

from acslam.config import CameraConfig, SlamConfig
from acslam.sim.camera import CameraSensor
from acslam.slam.factors import sensor_covariance

# Room 8 m x 4 m, a full wall at x in [5.0, 5.05). Robot at (2, 2) looking along +x.
POSE = (2.0, 2.0, 0.0)
LANDMARKS = np.array(
    [
        [3.0, 2.2, 0.5],  # 0: ahead, visible
        [4.9, 2.0, 0.3],  # 1: just before the wall face at x = 5.0, visible
        [5.2, 2.0, 0.3],  # 2: behind the wall, occluded
        [1.0, 2.0, 0.5],  # 3: behind the robot
        [2.0, 3.0, 0.5],  # 4: 90 deg left, outside the 70 deg FOV
        [2.1, 2.0, 0.5],  # 5: closer than range_min
        [4.5, 3.1, 0.8],  # 6: about 24 deg left, 2.7 m, visible
        [2.3, 3.94, 0.4],  # 7: at the room's top wall face, bearing 81 deg: outside FOV
        [3.5, 0.06, 0.2],  # 8: next to the bottom wall at bearing -52 deg: outside FOV
        [3.6, 0.9, 0.2],  # 9: bearing -34.5 deg, 1.94 m: visible
    ]
)
VISIBLE = {0, 1, 6, 9}


def _sensor(noise_std_m: float, seed: int = 0, **kwargs: float) -> CameraSensor:
    world = box_world(8.0, 4.0, wall_cols=(100,))
    config = CameraConfig(noise_std_m=noise_std_m, **kwargs)
    return CameraSensor(config, world, LANDMARKS, np.random.default_rng(seed))


def test_visible_landmarks_are_exact_in_robot_frame() -> None:
    for theta in (0.0, 0.3):
        pose = (POSE[0], POSE[1], theta)
        message, ids = _sensor(0.0).observe(2, 1.5, pose)
        assert message.robot_id == 2 and message.stamp == 1.5
        c, s = math.cos(theta), math.sin(theta)
        dx, dy = LANDMARKS[ids, 0] - pose[0], LANDMARKS[ids, 1] - pose[1]
        # R^T (l - t), written out: exactly the same floating-point result.
        assert np.array_equal(message.points[:, 0], c * dx + s * dy)
        assert np.array_equal(message.points[:, 1], -s * dx + c * dy)
        assert np.array_equal(message.points[:, 2], LANDMARKS[ids, 2])
    _, ids = _sensor(0.0).observe(0, 0.0, POSE)
    assert set(ids.tolist()) == VISIBLE


def test_range_limit_and_occlusion_by_a_wall() -> None:
    _, ids = _sensor(0.0, range_max_m=2.5).observe(0, 0.0, POSE)
    assert set(ids.tolist()) == {0, 9}
    # Seen from beyond the wall, landmark 2 is visible and 1 (behind the wall) is not.
    _, ids = _sensor(0.0).observe(0, 0.0, (7.0, 2.0, math.pi))
    assert 2 in ids and 1 not in ids


def test_nothing_visible_gives_an_empty_message() -> None:
    message, ids = _sensor(0.0).observe(0, 0.0, (7.0, 2.0, math.pi / 2))
    assert message.points.shape == (0, 3) and ids.size == 0


def test_noise_std_matches_and_order_is_shuffled() -> None:
    sensor = _sensor(0.05, seed=4)
    exact = _sensor(0.0)
    errors = []
    orders = set()
    for _ in range(500):
        message, ids = sensor.observe(0, 0.0, POSE)
        truth, truth_ids = exact.observe(0, 0.0, POSE)
        order = np.argsort(ids)
        errors.append(message.points[order] - truth.points[np.argsort(truth_ids)])
        orders.add(tuple(ids.tolist()))
    assert len(orders) > 1  # message order does not give identities away
    errors = np.concatenate(errors)
    assert np.all(np.abs(errors.std(axis=0) / 0.05 - 1.0) < 0.1)
    assert np.all(np.abs(errors.mean(axis=0)) < 0.01)


def test_the_default_landmark_factor_is_consistent_with_the_default_camera() -> None:
    """The localizer's default landmark noise is the default camera's: the squared
    Mahalanobis error of its points, at the true pose and landmark, averages the 3 of a
    3-dof chi-square (within 3 sigma of that mean over 2,000 points). A factor sigma of
    0.1 m, the old default, gives 0.27."""
    camera = CameraSensor(
        CameraConfig(), box_world(8.0, 4.0, wall_cols=(100,)), LANDMARKS, np.random.default_rng(11)
    )
    exact = _sensor(0.0)
    truth, truth_ids = exact.observe(0, 0.0, POSE)
    truth_points = truth.points[np.argsort(truth_ids)]
    squared = []
    for _ in range(500):
        message, ids = camera.observe(0, 0.0, POSE)
        for point, true_point in zip(message.points[np.argsort(ids)], truth_points, strict=True):
            covariance = sensor_covariance(SlamConfig(), point)
            error = point - true_point
            squared.append(float(error @ np.linalg.solve(covariance, error)))
    assert len(squared) == 2000
    assert abs(np.mean(squared) - 3.0) < 3 * math.sqrt(6.0 / len(squared))
