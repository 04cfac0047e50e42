"""Odometry noise statistics (eqs. 4.73-4.75) and noise-free exactness."""

from __future__ import annotations

import math

import numpy as np

from acslam.config import OdometryConfig
from acslam.seeding import Stream, rng
from acslam.sim.kinematics import step_pose
from acslam.sim.odometry import OdometryModel

START = (0.0, 0.0, 0.0)


def _models(config: OdometryConfig, count: int, dt_s: float = 0.02) -> list[OdometryModel]:
    return [
        OdometryModel(0, config, START, dt_s, rng(seed, Stream.ODOMETRY, 0))
        for seed in range(count)
    ]


def test_scale_errors_and_initial_biases_have_configured_spread() -> None:
    config = OdometryConfig(
        scale_v_std=0.03, scale_omega_std=0.05, bias_v_std_mps=0.004, bias_omega_std_radps=0.02
    )
    models = _models(config, 1000)
    for attribute, std in [
        ("scale_v_error", 0.03),
        ("scale_omega_error", 0.05),
        ("bias_v_mps", 0.004),
        ("bias_omega_radps", 0.02),
    ]:
        values = np.array([getattr(m, attribute) for m in models])
        assert abs(values.std() / std - 1.0) < 0.1, attribute


def test_bias_stays_stationary_while_running() -> None:
    config = OdometryConfig(
        bias_v_std_mps=0.004, bias_omega_std_radps=0.02, bias_correlation_time_s=1.0
    )
    models = _models(config, 1000)
    for _ in range(150):  # three correlation times
        for model in models:
            model.step(0.0, 0.0)
    assert abs(np.std([m.bias_v_mps for m in models]) / 0.004 - 1.0) < 0.1
    assert abs(np.std([m.bias_omega_radps for m in models]) / 0.02 - 1.0) < 0.1


def test_bias_autocorrelation_decays_with_correlation_time() -> None:
    dt_s, tau_s = 0.02, 1.0
    config = OdometryConfig(bias_correlation_time_s=tau_s)
    model = OdometryModel(0, config, START, dt_s, rng(7, Stream.ODOMETRY, 0))
    biases = np.empty(50_000)
    for k in range(biases.size):
        model.step(0.0, 0.0)
        biases[k] = model.bias_omega_radps
    centred = biases - biases.mean()
    for lag in (10, 25, 50):
        rho = np.dot(centred[:-lag], centred[lag:]) / np.dot(centred, centred)
        assert abs(rho - math.exp(-lag * dt_s / tau_s)) < 0.1, lag


def test_noise_free_odometry_reproduces_the_kinematics_exactly() -> None:
    config = OdometryConfig(
        bias_v_std_mps=0.0, bias_omega_std_radps=0.0, scale_v_std=0.0, scale_omega_std=0.0
    )
    dt_s = 0.02
    model = OdometryModel(3, config, (1.0, 2.0, 0.5), dt_s, rng(0, Stream.ODOMETRY, 3))
    truth = (1.0, 2.0, 0.5)
    for k in range(200):
        v, omega = 0.2 * math.sin(0.05 * k), 0.8 * math.cos(0.03 * k)
        model.step(v, omega)
        truth = step_pose(*truth, v, omega, dt_s)
    assert model.pose == truth
    increment = model.emit(4.0)
    assert increment.robot_id == 3 and increment.start_stamp == 0.0 and increment.stamp == 4.0
    second = model.emit(4.5)
    assert second.start_stamp == 4.0 and second.delta.tolist() == [0.0, 0.0, 0.0]


def test_biased_robot_drifts_at_standstill() -> None:
    config = OdometryConfig(bias_v_std_mps=0.01, bias_omega_std_radps=0.0, scale_v_std=0.0)
    model = OdometryModel(0, config, START, 0.02, rng(1, Stream.ODOMETRY, 0))
    for _ in range(50):
        model.step(0.0, 0.0)
    increment = model.emit(1.0)
    assert increment.dx != 0.0 and abs(increment.dx) < 0.1
