"""Online odometry calibration against odometry with known scale errors and biases, the
thesis's odometry model (eqs. 4.73-4.75) with the biases held still or drifting."""

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


def _drive(
    truth_error: np.ndarray, duration_s: float, seed: int, turn_bias_walk: float = 0.0
) -> tuple[np.ndarray, list[OdometryIncrement]]:
    """True poses at every odometry stamp, and the raw increments of odometry whose speed
    is (1 + scale) v + bias and turn rate (1 + scale) omega + bias, while the robot
    drives at changing speeds and turn rates (and now and then stands still)."""
    scale_travel, travel_bias, scale_turn, turn_bias = truth_error
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE_HZ
    truth = [np.zeros(3)]
    measured = np.zeros(3)
    increments = []
    v = omega = 0.0
    for k in range(int(duration_s * RATE_HZ)):
        if k % int(4 * RATE_HZ) == 0:  # a new command every 4 s
            v = rng.choice([0.0, rng.uniform(0.1, 0.3)], p=[0.1, 0.9])
            omega = rng.uniform(-0.6, 0.6)
        turn_bias += turn_bias_walk * np.sqrt(dt) * rng.standard_normal()
        truth.append(np.array(step_pose(*truth[-1], v, omega, dt)))
        v_m = (1 + scale_travel) * v + travel_bias
        omega_m = (1 + scale_turn) * omega + turn_bias
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
def test_constant_errors_are_learned_within_their_sigmas(seed: int) -> None:
    truth_error = np.array([0.03, 0.005, -0.025, 0.002])
    truth, increments = _drive(truth_error, 600.0, seed)
    calibration, _ = _calibrate(SlamConfig(), truth, increments, seed)
    sigmas = np.sqrt(np.diag(calibration.covariance))
    assert np.all(np.abs(calibration.mean - truth_error) <= 3.0 * sigmas)
    # Tight enough to matter: each well below the error it corrects (the turn bias less
    # so: the configured random walk lets it wander, as odometry's does).
    assert sigmas[0] < 0.005 and sigmas[2] < 0.002 and sigmas[3] < 0.001
    assert calibration.rejected == 0


def test_corrected_odometry_keeps_its_heading_where_raw_odometry_drifts() -> None:
    """The last 5 minutes of a 10-minute drive, with a drifting turn bias: the heading
    integrated from the corrected increments drifts a fifth as much as the raw one (the
    bias keeps wandering, so what is left is its error since the latest matches)."""
    truth_error = np.array([0.02, 0.0, 0.02, 0.002])
    truth, increments = _drive(truth_error, 600.0, seed=4, turn_bias_walk=0.0005)
    _, corrected = _calibrate(SlamConfig(), truth, increments, seed=4)
    half = len(increments) // 2

    def heading_drift(chain: list[OdometryIncrement]) -> float:
        pose = truth[half].copy()
        for increment in chain[half:]:
            pose = compose(pose, increment.delta)
        return abs(wrap_angle(pose[2] - truth[-1][2]))

    raw, fixed = heading_drift(increments), heading_drift(corrected)
    assert raw > 0.3  # the raw bias and scale turn the estimate by a lot in 5 minutes
    assert fixed < 0.2 * raw


def test_a_match_that_odometry_contradicts_is_not_used() -> None:
    truth, increments = _drive(np.zeros(4), 60.0, seed=5)
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
