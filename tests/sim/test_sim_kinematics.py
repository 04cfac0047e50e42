"""Eq. 4.72 against the closed-form arc, and the command limits."""

from __future__ import annotations

import itertools
import math

import numpy as np

from acslam.config import RobotsConfig
from acslam.sim.kinematics import limit_command, step_pose


def _integrate(v: float, omega: float, duration_s: float, dt_s: float) -> tuple[float, ...]:
    pose = (1.0, -2.0, 0.3)
    for _ in range(round(duration_s / dt_s)):
        pose = step_pose(*pose, v, omega, dt_s)
    return pose


def _position_error(v: float, omega: float, duration_s: float, dt_s: float) -> float:
    x0, y0, th0 = 1.0, -2.0, 0.3
    th = th0 + omega * duration_s
    x = x0 + v / omega * (math.sin(th) - math.sin(th0))
    y = y0 - v / omega * (math.cos(th) - math.cos(th0))
    ex, ey, eth = _integrate(v, omega, duration_s, dt_s)
    assert abs(math.remainder(eth - th, 2 * math.pi)) < 1e-9  # the heading is exact
    return math.hypot(ex - x, ey - y)


def test_arc_matches_closed_form_with_first_order_error() -> None:
    v, omega, duration_s = 0.5, 0.7, 4.0
    errors = []
    for dt_s in (0.01, 0.005, 0.0025):
        error = _position_error(v, omega, duration_s, dt_s)
        # Each step's chord leaves the arc by at most |v||omega|dt^2/2: bound |v||omega|T dt/2.
        assert error <= abs(v * omega) * duration_s * dt_s / 2
        errors.append(error)
    for coarse, fine in itertools.pairwise(errors):
        assert 1.8 < coarse / fine < 2.2  # first order: halving dt halves the error


def test_straight_line_is_exact() -> None:
    x, y, th = _integrate(0.3, 0.0, 5.0, 0.02)
    assert math.isclose(x, 1.0 + 1.5 * math.cos(0.3), abs_tol=1e-12)
    assert math.isclose(y, -2.0 + 1.5 * math.sin(0.3), abs_tol=1e-12)
    assert math.isclose(th, 0.3, abs_tol=1e-15)


def test_heading_is_wrapped() -> None:
    _, _, th = step_pose(0.0, 0.0, 3.1, 0.0, 2.0, 0.1)
    assert -math.pi <= th < math.pi
    assert math.isclose(th, 3.3 - 2 * math.pi)


def test_speed_and_acceleration_limits_hold() -> None:
    limits = RobotsConfig()
    dt_s = 0.02
    rng = np.random.default_rng(3)
    v, omega = 0.0, 0.0
    for _ in range(2000):
        cmd_v, cmd_omega = rng.uniform(-1.0, 1.0), rng.uniform(-6.0, 6.0)
        new_v, new_omega = limit_command(cmd_v, cmd_omega, v, omega, limits, dt_s)
        assert abs(new_v) <= limits.max_v_mps
        assert abs(new_omega) <= limits.max_omega_radps
        assert abs(new_v - v) <= limits.max_acc_v_mps2 * dt_s + 1e-12
        assert abs(new_omega - omega) <= limits.max_acc_omega_radps2 * dt_s + 1e-12
        v, omega = new_v, new_omega


def test_reachable_command_is_taken_as_is() -> None:
    assert limit_command(0.1, -0.5, 0.1, -0.5, RobotsConfig(), 0.02) == (0.1, -0.5)
    assert limit_command(0.105, -0.52, 0.1, -0.5, RobotsConfig(), 0.02) == (0.105, -0.52)
