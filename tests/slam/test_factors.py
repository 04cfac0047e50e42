"""Custom factor Jacobians against central differences through GTSAM's own retract."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from acslam.config import SlamConfig
from acslam.geometry import compose
from acslam.slam import keys
from acslam.slam.association import pose_lever_jacobian
from acslam.slam.factors import (
    observation_factor,
    observation_noise,
    odometry_sigmas,
    planar_compose_jacobians,
    planar_to_pose2,
    point_to_body,
    point_to_world,
    pose2_to_planar,
    robot_observation_factor,
    rotation_about_z,
    sensor_covariance,
)

POSE = keys.pose_key(3, 7)
LANDMARK = keys.landmark_key(11)


def _random_pose(rng: np.random.Generator) -> gtsam.Pose2:
    return gtsam.Pose2.Expmap(rng.normal(size=3))


def _error(factor: gtsam.CustomFactor, pose: gtsam.Pose2, point: np.ndarray) -> np.ndarray:
    values = gtsam.Values()
    values.insert(POSE, pose)
    values.insert(LANDMARK, gtsam.Point3(*point))
    return np.asarray(factor.unwhitenedError(values))


def _central_differences(error_at, dim: int, eps: float = 1e-6) -> np.ndarray:
    """(3, dim) Jacobian of ``error_at(step)`` at step = 0 by central differences."""
    return np.column_stack(
        [(error_at(eps * e) - error_at(-eps * e)) / (2 * eps) for e in np.eye(dim)]
    )


@pytest.mark.parametrize("seed", range(6))
def test_observation_jacobians_match_central_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pose, point = _random_pose(rng), rng.normal(size=3) * 3
    factor = observation_factor(POSE, LANDMARK, rng.normal(size=3), gtsam.noiseModel.Unit.Create(3))
    values = gtsam.Values()
    values.insert(POSE, pose)
    values.insert(LANDMARK, gtsam.Point3(*point))
    # With a unit noise model the linearised factor holds the raw Jacobians.
    linear = factor.linearize(values)
    h_pose, h_point = np.asarray(linear.getA()[:, :3]), np.asarray(linear.getA()[:, 3:])
    num_pose = _central_differences(lambda step: _error(factor, pose.retract(step), point), 3)
    num_point = _central_differences(lambda step: _error(factor, pose, point + step), 3)
    np.testing.assert_allclose(h_pose, num_pose, atol=1e-6)
    np.testing.assert_allclose(h_point, num_point, atol=1e-6)


OBSERVED = keys.pose_key(4, 2)


def _robot_error(factor: gtsam.CustomFactor, pose_a: gtsam.Pose2, pose_b: gtsam.Pose2):
    values = gtsam.Values()
    values.insert(POSE, pose_a)
    values.insert(OBSERVED, pose_b)
    return np.asarray(factor.unwhitenedError(values))


@pytest.mark.parametrize("seed", range(6))
def test_robot_observation_jacobians_match_central_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pose_a, pose_b = _random_pose(rng), _random_pose(rng)
    factor = robot_observation_factor(
        POSE, OBSERVED, rng.normal(size=3), rng.normal(size=3), gtsam.noiseModel.Unit.Create(3)
    )
    values = gtsam.Values()
    values.insert(POSE, pose_a)
    values.insert(OBSERVED, pose_b)
    linear = factor.linearize(values)
    h_a, h_b = np.asarray(linear.getA()[:, :3]), np.asarray(linear.getA()[:, 3:])
    num_a = _central_differences(lambda step: _robot_error(factor, pose_a.retract(step), pose_b), 3)
    num_b = _central_differences(lambda step: _robot_error(factor, pose_a, pose_b.retract(step)), 3)
    np.testing.assert_allclose(h_a, num_a, atol=1e-6)
    np.testing.assert_allclose(h_b, num_b, atol=1e-6)


def test_robot_observation_error_of_a_known_configuration() -> None:
    # Observer at the origin facing +x; the observed keyframe at (2, 1) facing +y, and the
    # observed robot 0.5 m ahead of that keyframe: at (2, 1.5) -> measured (1.9, 1.6, 0)
    # gives e = (0.1, -0.1, 0).
    factor = robot_observation_factor(
        POSE,
        OBSERVED,
        np.array([1.9, 1.6, 0.0]),
        np.array([0.5, 0.0, 0.0]),
        gtsam.noiseModel.Unit.Create(3),
    )
    error = _robot_error(
        factor, planar_to_pose2(np.zeros(3)), planar_to_pose2(np.array([2.0, 1.0, np.pi / 2]))
    )
    np.testing.assert_allclose(error, [0.1, -0.1, 0.0], atol=1e-12)


def test_observation_error_of_a_known_configuration() -> None:
    # Robot at (1, 2) facing +y; landmark at (1, 5, 0.5) is 3 m straight ahead, 0.5 m up:
    # R^T (l - t) = (3, 0, 0.5). Measured (2.9, 0.1, 0.5) -> e = (0.1, -0.1, 0).
    factor = observation_factor(
        POSE, LANDMARK, np.array([2.9, 0.1, 0.5]), gtsam.noiseModel.Unit.Create(3)
    )
    pose = planar_to_pose2(np.array([1.0, 2.0, np.pi / 2]))
    np.testing.assert_allclose(
        _error(factor, pose, np.array([1.0, 5.0, 0.5])), [0.1, -0.1, 0.0], atol=1e-12
    )


def test_observation_noise_scales_information_by_probability() -> None:
    cov = np.diag([0.01, 0.04, 0.09])
    noise = observation_noise(cov, 0.25, huber_k=100.0)
    # Huber with a huge threshold is plain Gaussian: whitened error = sqrt(p) Sigma^-1/2 e.
    e = np.array([0.1, 0.2, 0.3])
    np.testing.assert_allclose(noise.whiten(e), 0.5 * e / np.sqrt(np.diag(cov)), atol=1e-12)
    with pytest.raises(ValueError):
        observation_noise(cov, 0.0, 1.0)


@pytest.mark.parametrize("seed", range(4))
def test_pose_lever_jacobian_matches_retract(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pose, point = _random_pose(rng), rng.normal(size=3)
    eps = 1e-6
    numeric = np.column_stack(
        [
            (
                point_to_world(pose.retract(eps * e), point)
                - point_to_world(pose.retract(-eps * e), point)
            )
            / (2 * eps)
            for e in np.eye(3)
        ]
    )
    np.testing.assert_allclose(
        pose_lever_jacobian(rotation_about_z(pose.theta()), point), numeric, atol=1e-6
    )


@pytest.mark.parametrize("seed", range(4))
def test_a_point_to_the_body_frame_and_back_is_the_point_and_keeps_its_height(seed: int) -> None:
    """point_to_body inverts point_to_world; its Jacobians match central differences
    through GTSAM's retract; the pose never moves z."""
    rng = np.random.default_rng(seed)
    pose, point = _random_pose(rng), rng.normal(size=3) * 3
    body, h_pose, h_point = point_to_body(pose, point)
    np.testing.assert_allclose(point_to_world(pose, body), point, atol=1e-12)
    assert body[2] == point[2]
    num_pose = _central_differences(lambda step: point_to_body(pose.retract(step), point)[0], 3)
    num_point = _central_differences(lambda step: point_to_body(pose, point + step)[0], 3)
    np.testing.assert_allclose(h_pose, num_pose, atol=1e-6)
    np.testing.assert_allclose(h_point, num_point, atol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_planar_compose_jacobians(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=3), rng.normal(size=3)
    ja, jb = planar_compose_jacobians(a, b)
    eps = 1e-6
    for jac, which in ((ja, 0), (jb, 1)):
        cols = []
        for e in np.eye(3):
            plus = compose(a + eps * e, b) if which == 0 else compose(a, b + eps * e)
            minus = compose(a - eps * e, b) if which == 0 else compose(a, b - eps * e)
            cols.append((plus - minus) / (2 * eps))
        np.testing.assert_allclose(jac, np.column_stack(cols), atol=1e-6)


def test_planar_round_trip_and_odometry_sigmas() -> None:
    pose = np.array([1.5, -2.0, 2.5])
    np.testing.assert_allclose(pose2_to_planar(planar_to_pose2(pose)), pose, atol=1e-12)
    config = SlamConfig()
    floor = odometry_sigmas(config, 0.0, 0.0)
    assert floor[0] == config.odom_sigma_min_xy_m
    far = odometry_sigmas(config, 10.0, 0.0)
    assert far[0] == pytest.approx(config.odom_sigma_xy_per_m * 10.0)


def test_key_scheme_round_trips_beyond_26_robots() -> None:
    for robot, index in ((0, 0), (30, 12345), (keys.MAX_ROBOTS - 1, keys.MAX_INDEX - 1)):
        assert keys.decode_pose_key(keys.pose_key(robot, index)) == (robot, index)
    assert keys.decode_landmark_key(keys.landmark_key(42)) == 42
    assert keys.is_pose_key(keys.pose_key(1, 2)) and not keys.is_pose_key(keys.landmark_key(2))
    assert keys.describe(keys.pose_key(30, 4)) == "robot 30 keyframe 4"
    with pytest.raises(ValueError):
        keys.pose_key(keys.MAX_ROBOTS, 0)


def test_sensor_covariance_grows_along_the_ray_with_range() -> None:
    """A point 4 m out along a direction at 30 degrees: along the ray the variance is
    iso^2 + radial^2 + (per_m x 4 m)^2, across it iso^2 + (4 m x angular)^2, and the two
    axes are the ray and its normal (eigenvectors)."""
    config = SlamConfig(
        landmark_sigma_m=0.03,
        landmark_radial_sigma_m=0.02,
        landmark_radial_sigma_per_m=0.05,
        landmark_angular_sigma_rad=0.01,
    )
    ray = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6), 0.0])
    cov = sensor_covariance(config, 4.0 * ray)
    normal = np.array([-ray[1], ray[0], 0.0])
    assert ray @ cov @ ray == pytest.approx(0.03**2 + 0.02**2 + 0.2**2)
    assert normal @ cov @ normal == pytest.approx(0.03**2 + 0.04**2)
    assert ray @ cov @ normal == pytest.approx(0.0, abs=1e-15)
    near = sensor_covariance(config, 1.0 * ray)
    assert ray @ near @ ray == pytest.approx(0.03**2 + 0.02**2 + 0.05**2)
