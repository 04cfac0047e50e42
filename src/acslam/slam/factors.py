"""Factors and noise models of the SLAM graph, and planar <-> ``gtsam.Pose2`` conversions.

Thesis eq. 4.7 writes the poses in SE(3). The robots are planar, so their z, roll and
pitch never change: the graph holds ``gtsam.Pose2`` (GTSAM's tangent ``[x, y, theta]``, in
the body frame), which gives iSAM2 three columns per pose instead of six and dense blocks a
quarter the size. Landmarks stay ``Point3`` (a camera sees them at a height); a planar pose
moves their x and y and leaves their z as measured.
"""

from __future__ import annotations

import math
from functools import partial

import gtsam
import numpy as np

from acslam.config import SlamConfig


def planar_to_pose2(pose: np.ndarray) -> gtsam.Pose2:
    """``[x, y, theta]`` -> Pose2."""
    return gtsam.Pose2(float(pose[0]), float(pose[1]), float(pose[2]))


def pose2_to_planar(pose: gtsam.Pose2) -> np.ndarray:
    """Pose2 -> ``[x, y, theta]``."""
    return np.array([pose.x(), pose.y(), pose.theta()])


def rotation_about_z(theta_rad: float) -> np.ndarray:
    """3x3 rotation by ``theta_rad`` about z: a planar pose's rotation acting on 3D points."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def point_to_world(pose: gtsam.Pose2, point: np.ndarray) -> np.ndarray:
    """A 3D point in the pose's frame -> the world frame (z unchanged)."""
    xy = pose.transformFrom(np.asarray(point[:2], dtype=float))
    return np.array([xy[0], xy[1], point[2]])


def point_to_body(
    pose: gtsam.Pose2, point: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A world 3D point in the pose's frame, and the 3x3 Jacobians of that with respect to
    the pose (GTSAM's Pose2 chart, which iSAM2 retracts with) and to the point."""
    h_pose2 = np.zeros((2, 3), order="F")
    h_point2 = np.zeros((2, 2), order="F")
    xy = pose.transformTo(np.asarray(point[:2], dtype=float), h_pose2, h_point2)
    h_pose = np.zeros((3, 3))
    h_pose[:2] = h_pose2
    h_point = np.zeros((3, 3))
    h_point[:2, :2] = h_point2
    h_point[2, 2] = 1.0
    return np.array([xy[0], xy[1], point[2]]), h_pose, h_point


def prior_noise(config: SlamConfig) -> gtsam.noiseModel.Base:
    """Known start pose: ``[x, y, theta]`` sigmas."""
    xy, th = config.prior_sigma_xy_m, config.prior_sigma_theta_rad
    return gtsam.noiseModel.Diagonal.Sigmas(np.array([xy, xy, th]))


def odometry_sigmas(config: SlamConfig, distance_m: float, angle_rad: float) -> np.ndarray:
    """Planar ``[sigma_x, sigma_y, sigma_theta]`` of an odometry increment.

    Grows linearly with the path length and the absolute turn travelled (the increment is
    a sum of independent small steps, so linear in std is conservative against the
    sqrt a random walk would give; it also covers the correlated bias of real odometry).
    """
    sigma_xy = max(config.odom_sigma_min_xy_m, config.odom_sigma_xy_per_m * distance_m)
    sigma_theta = max(
        config.odom_sigma_min_theta_rad,
        config.odom_sigma_theta_per_rad * angle_rad + config.odom_sigma_theta_per_m * distance_m,
    )
    return np.array([sigma_xy, sigma_xy, sigma_theta])


def odometry_noise(
    config: SlamConfig, distance_m: float, angle_rad: float
) -> gtsam.noiseModel.Base:
    """Noise of a BetweenFactorPose2 between consecutive keyframes."""
    return gtsam.noiseModel.Diagonal.Sigmas(odometry_sigmas(config, distance_m, angle_rad))


def radial_variance_m2(config: SlamConfig, distance_m: float | np.ndarray) -> float | np.ndarray:
    """Variance along the line of sight beyond the isotropic part: a constant, and a part
    that grows with the range."""
    return (
        config.landmark_radial_sigma_m**2 + (distance_m * config.landmark_radial_sigma_per_m) ** 2
    )


def sensor_covariance(config: SlamConfig, point: np.ndarray) -> np.ndarray:
    """3x3 covariance of an observed point (robot frame): isotropic, plus radial (a
    constant and a part proportional to the range) and angular."""
    cov = np.eye(3) * config.landmark_sigma_m**2
    distance = float(np.linalg.norm(point))
    if distance > 0.0:
        ray = np.outer(point, point) / distance**2
        cov += radial_variance_m2(config, distance) * ray
        cov += (distance * config.landmark_angular_sigma_rad) ** 2 * (np.eye(3) - ray)
    return cov


def observation_noise(
    covariance: np.ndarray, probability: float, huber_k: float
) -> gtsam.noiseModel.Base:
    """Huber-robust Gaussian noise of an observation, weighted by its association probability.

    A soft association with probability ``p`` enters as a factor whose information is
    ``p * Sigma^-1`` (covariance ``Sigma / p``), so its pull on the estimate scales with p.
    """
    if not 0.0 < probability <= 1.0:
        raise ValueError(f"association probability must be in (0, 1], got {probability}")
    gaussian = gtsam.noiseModel.Gaussian.Covariance(np.asarray(covariance) / probability)
    return gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Huber.Create(huber_k), gaussian
    )


def _observation_error(
    measured: np.ndarray,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[np.ndarray] | None,
) -> np.ndarray:
    """e = [R_i^T (l_j - t_i), z_lj] - z: the predicted landmark in the robot frame minus
    the measurement.

    Thesis eq. 4.13 writes e = l_j - t_i, which drops both the measurement z and the
    robot's rotation R_i; that residual is not zero at the true configuration unless the
    robot sits at the origin unrotated, so we use the full model.
    """
    keys = this.keys()
    predicted, h_pose, h_landmark = point_to_body(values.atPose2(keys[0]), values.atPoint3(keys[1]))
    if jacobians is not None:
        jacobians[0] = h_pose
        jacobians[1] = h_landmark
    return predicted - measured


def observation_factor(
    pose_key: int, landmark_key: int, measured: np.ndarray, noise: gtsam.noiseModel.Base
) -> gtsam.CustomFactor:
    """Landmark ``measured`` (3D point, robot frame) seen from pose ``pose_key``."""
    measured = np.asarray(measured, dtype=float).reshape(3)
    return gtsam.CustomFactor(
        noise, [pose_key, landmark_key], partial(_observation_error, measured)
    )


def _robot_observation_error(
    measured: np.ndarray,
    target: np.ndarray,
    this: gtsam.CustomFactor,
    values: gtsam.Values,
    jacobians: list[np.ndarray] | None,
) -> np.ndarray:
    """e = T_a^-1 (T_b p) - z: robot b's point ``p`` (its own frame) predicted in a's frame.

    ``p`` is where robot b was, relative to its keyframe, when robot a measured it (the
    odometry since that keyframe), so both robots' keyframes take the correction.
    """
    keys = this.keys()
    pose_a = values.atPose2(keys[0])
    pose_b = values.atPose2(keys[1])
    h_b2 = np.zeros((2, 3), order="F")
    world = pose_b.transformFrom(target[:2], h_b2, np.zeros((2, 2), order="F"))
    predicted, h_a, h_world = point_to_body(pose_a, np.array([world[0], world[1], target[2]]))
    if jacobians is not None:
        h_b = np.zeros((3, 3))
        h_b[:2] = h_b2
        jacobians[0] = h_a
        jacobians[1] = h_world @ h_b
    return predicted - measured


def robot_observation_factor(
    observer_key: int,
    observed_key: int,
    measured: np.ndarray,
    target: np.ndarray,
    noise: gtsam.noiseModel.Base,
) -> gtsam.CustomFactor:
    """Robot ``observed_key`` seen from ``observer_key`` at ``measured`` (3D point in the
    observer's frame); ``target`` is the seen point in the observed pose's own frame."""
    measured = np.asarray(measured, dtype=float).reshape(3)
    target = np.asarray(target, dtype=float).reshape(3)
    return gtsam.CustomFactor(
        noise,
        [observer_key, observed_key],
        partial(_robot_observation_error, measured, target),
    )


def planar_compose_jacobians(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of SE(2) ``a * b`` w.r.t. ``a`` and ``b`` (world-frame [x, y, theta])."""
    c, s = math.cos(a[2]), math.sin(a[2])
    ja = np.array(
        [[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]]
    )
    return ja, rotation_about_z(a[2])
