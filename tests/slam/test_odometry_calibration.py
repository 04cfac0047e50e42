"""Online odometry calibration against odometry with known scale errors, with and
without the biases of the thesis's odometry model (eqs. 4.73-4.75)."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.config import SlamConfig
from acslam.geometry import between, compose, wrap_angle
from acslam.messages import OdometryIncrement
from acslam.sim.kinematics import step_pose
from acslam.slam.backend import SlamBackend
from acslam.slam.odometry_calibration import OdometryCalibration

RATE_HZ = 20.0
MATCH_SIGMAS = np.array([0.005, 0.005, 0.002])  # m, m, rad: a sequential scan match
SIMULATED_BIAS_STDS = (0.005, 0.002)  # m/s, rad/s: OdometryConfig's


def _drive(
    scales: tuple[float, float], duration_s: float, seed: int, bias_stds: tuple[float, float]
) -> tuple[np.ndarray, list[OdometryIncrement]]:
    """True poses at every odometry stamp, and the raw increments of odometry whose speed
    is (1 + scale) v + bias and turn rate (1 + scale) omega + bias, the biases wandering
    as the simulated robot's (Gauss-Markov, 30 s), while the robot drives at changing
    speeds and turn rates (and now and then stands still)."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE_HZ
    decay = np.exp(-dt / 30.0)
    biases = np.asarray(bias_stds) * rng.standard_normal(2)
    truth = [np.zeros(3)]
    measured = np.zeros(3)
    increments = []
    v = omega = 0.0
    for k in range(int(duration_s * RATE_HZ)):
        if k % int(4 * RATE_HZ) == 0:  # a new command every 4 s
            v = rng.choice([0.0, rng.uniform(0.1, 0.3)], p=[0.1, 0.9])
            omega = rng.uniform(-0.6, 0.6)
        biases = decay * biases + np.sqrt(1 - decay**2) * np.asarray(bias_stds) * (
            rng.standard_normal(2)
        )
        truth.append(np.array(step_pose(*truth[-1], v, omega, dt)))
        v_m = (1 + scales[0]) * v + biases[0]
        omega_m = (1 + scales[1]) * omega + biases[1]
        after = np.array(step_pose(*measured, v_m, omega_m, dt))
        delta = between(measured, after)
        delta[2] = omega_m * dt  # unwrapped, as odometry reports it
        increments.append(OdometryIncrement(0, (k + 1) * dt, k * dt, *delta))
        measured = after
    return np.array(truth), increments


def _calibrate(
    config: SlamConfig, truth: np.ndarray, increments: list[OdometryIncrement], seed: int
) -> tuple[OdometryCalibration, list[OdometryIncrement]]:
    """Feed the increments; every 1.5 s, a scan match of the true motion since the last
    one, with the noise of a sequential match."""
    rng = np.random.default_rng(seed + 1)
    calibration = OdometryCalibration(config)
    corrected = []
    every = int(1.5 * RATE_HZ)
    for k, increment in enumerate(increments, start=1):
        corrected.append(calibration.correct(increment))
        if k % every == 0:
            relative = between(truth[k - every], truth[k]) + MATCH_SIGMAS * rng.standard_normal(3)
            relative[2] = wrap_angle(relative[2])
            stamps = (increments[k - every - 1].stamp if k > every else 0.0, increment.stamp)
            calibration.update(*stamps, relative, np.diag(MATCH_SIGMAS**2))
    return calibration, corrected


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_scale_errors_are_learned_despite_wandering_biases(seed: int) -> None:
    """With the simulated robot's biases (0.005 m/s, 0.002 rad/s) wandering beside them,
    10 minutes of matches pin the scales within 3 sigma, and those sigmas well below the
    2-3 % errors they correct."""
    truth, increments = _drive((0.03, -0.025), 600.0, seed, SIMULATED_BIAS_STDS)
    calibration, _ = _calibrate(SlamConfig(), truth, increments, seed)
    sigmas = np.sqrt(np.diag(calibration.covariance))
    assert abs(calibration.scale_travel - 0.03) <= 3.0 * sigmas[0] and sigmas[0] < 0.005
    assert abs(calibration.scale_turn + 0.025) <= 3.0 * sigmas[2] and sigmas[2] < 0.001
    assert calibration.rejected == 0


def test_corrected_odometry_keeps_its_heading_where_raw_odometry_drifts() -> None:
    """A 2 % turn-rate scale error and no bias: over the last 5 minutes of a 10-minute
    drive, the heading integrated from the corrected increments drifts a tenth as much as
    the raw one."""
    truth, increments = _drive((0.02, 0.02), 600.0, 4, (0.0, 0.0))
    _, corrected = _calibrate(SlamConfig(), truth, increments, seed=4)
    half = len(increments) // 2

    def heading_drift(chain: list[OdometryIncrement]) -> float:
        pose = truth[half].copy()
        for increment in chain[half:]:
            pose = compose(pose, increment.delta)
        return abs(wrap_angle(pose[2] - truth[-1][2]))

    raw, fixed = heading_drift(increments), heading_drift(corrected)
    assert raw > 0.1  # 2 % of the turning the robot does in 5 minutes
    assert fixed < 0.1 * raw


def test_a_match_that_odometry_contradicts_is_not_used() -> None:
    truth, increments = _drive((0.0, 0.0), 60.0, 5, SIMULATED_BIAS_STDS)
    calibration, _ = _calibrate(SlamConfig(), truth, increments, seed=5)
    before = calibration.mean.copy()
    start, end = increments[-31].stamp, increments[-1].stamp
    wrong = between(truth[-31], truth[-1]) + np.array([0.0, 0.0, 0.2])
    assert not calibration.update(start, end, wrong, np.diag(MATCH_SIGMAS**2))
    assert calibration.rejected == 1 and np.array_equal(calibration.mean, before)
    # A span the raw odometry does not cover (not yet received) is not used either.
    assert not calibration.update(end, end + 1.0, np.zeros(3), np.diag(MATCH_SIGMAS**2))


def test_calibration_can_be_turned_off() -> None:
    start = {0: np.zeros(3)}
    assert SlamBackend(SlamConfig(odometry_calibration=False), start).odometry_calibrations() == {}
    summary = SlamBackend(SlamConfig(), start).odometry_calibrations()[0]
    assert summary["updates"] == 0 and summary["scale_turn"] == 0.0
