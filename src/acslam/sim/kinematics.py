"""Differential-drive ground truth (thesis eq. 4.72) and command limiting.

Plain ``math`` on floats: these run once per robot per step, where numpy scalars would
cost more than the arithmetic.
"""

from __future__ import annotations

import math

from acslam.config import RobotsConfig

_TWO_PI = 2.0 * math.pi


def step_pose(
    x_m: float, y_m: float, theta_rad: float, v_mps: float, omega_radps: float, dt_s: float
) -> tuple[float, float, float]:
    """One forward-Euler step of eq. 4.72; the heading is wrapped to [-pi, pi).

    For constant (v, omega) the heading is exact and the position error after time T is
    at most ``|v| |omega| T dt / 2`` (each step's chord deviates from the arc by at most
    ``|v| |omega| dt^2 / 2``).
    """
    x_m += v_mps * math.cos(theta_rad) * dt_s
    y_m += v_mps * math.sin(theta_rad) * dt_s
    theta_rad = (theta_rad + omega_radps * dt_s + math.pi) % _TWO_PI - math.pi
    return x_m, y_m, theta_rad


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def limit_command(
    v_cmd_mps: float,
    omega_cmd_radps: float,
    v_now_mps: float,
    omega_now_radps: float,
    limits: RobotsConfig,
    dt_s: float,
) -> tuple[float, float]:
    """The velocity the robot actually reaches this step for a command.

    The command is clipped to the speed limits, then the change from the current
    velocity to the acceleration limits times ``dt_s``.
    """
    v = _clip(v_cmd_mps, -limits.max_v_mps, limits.max_v_mps)
    omega = _clip(omega_cmd_radps, -limits.max_omega_radps, limits.max_omega_radps)
    dv_max = limits.max_acc_v_mps2 * dt_s
    domega_max = limits.max_acc_omega_radps2 * dt_s
    v = _clip(v, v_now_mps - dv_max, v_now_mps + dv_max)
    omega = _clip(omega, omega_now_radps - domega_max, omega_now_radps + domega_max)
    return v, omega
