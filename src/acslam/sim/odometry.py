"""The robot's own odometry/IMU estimate (thesis eqs. 4.73-4.75).

Each step the true (v, omega) is corrupted as v_m = (1 + eps_v) v + b_v and
omega_m = (1 + eps_omega) omega + b_omega, and integrated with the same kinematics as the
ground truth (eq. 4.72) into an estimated pose. The biases are first-order Gauss-Markov
processes in the continuous-time form of :class:`~acslam.config.OdometryConfig`. As in the
thesis model, the bias acts even at standstill, so a parked robot's estimate drifts like
an IMU's would.
"""

from __future__ import annotations

import math

import numpy as np

from acslam.config import OdometryConfig
from acslam.geometry import between
from acslam.messages import OdometryIncrement
from acslam.sim.kinematics import step_pose

_BLOCK_STEPS = 1024  # bias innovations drawn per numpy call, to keep the step cheap


class OdometryModel:
    """Integrates one robot's noisy velocity measurements and emits increments.

    Random draws, all from ``rng`` in this order: the two scale errors, the two initial
    biases (from the stationary distribution N(0, bias_std^2)), then the per-step bias
    innovations in blocks.
    """

    def __init__(
        self,
        robot_id: int,
        config: OdometryConfig,
        start_pose: tuple[float, float, float],
        dt_s: float,
        rng: np.random.Generator,
        start_stamp_s: float = 0.0,
    ) -> None:
        self.robot_id = robot_id
        self._dt_s = dt_s
        self._rng = rng
        self.scale_v_error = float(rng.normal(0.0, config.scale_v_std))
        self.scale_omega_error = float(rng.normal(0.0, config.scale_omega_std))
        self.bias_v_mps = float(rng.normal(0.0, config.bias_v_std_mps))
        self.bias_omega_radps = float(rng.normal(0.0, config.bias_omega_std_radps))
        a = math.exp(-dt_s / config.bias_correlation_time_s)
        self._bias_decay = a
        innovation = math.sqrt(1.0 - a * a)
        self._innovation_std = (
            config.bias_v_std_mps * innovation,
            config.bias_omega_std_radps * innovation,
        )
        self._innovations: list[list[float]] = []
        self._next_innovation = 0
        self.pose = start_pose
        self._emitted_pose = start_pose
        self._emitted_stamp_s = start_stamp_s

    def step(self, v_mps: float, omega_radps: float) -> None:
        """Advance the biases one step (eq. 4.73) and integrate the measured velocity."""
        if self._next_innovation == len(self._innovations):
            self._innovations = self._rng.standard_normal((_BLOCK_STEPS, 2)).tolist()
            self._next_innovation = 0
        n_v, n_omega = self._innovations[self._next_innovation]
        self._next_innovation += 1
        a = self._bias_decay
        self.bias_v_mps = a * self.bias_v_mps + self._innovation_std[0] * n_v
        self.bias_omega_radps = a * self.bias_omega_radps + self._innovation_std[1] * n_omega
        v_m = (1.0 + self.scale_v_error) * v_mps + self.bias_v_mps
        omega_m = (1.0 + self.scale_omega_error) * omega_radps + self.bias_omega_radps
        self.pose = step_pose(*self.pose, v_m, omega_m, self._dt_s)

    def emit(self, stamp_s: float) -> OdometryIncrement:
        """The estimated motion since the previous emission, in that emission's frame."""
        dx, dy, dtheta = between(np.array(self._emitted_pose), np.array(self.pose))
        start_stamp_s = self._emitted_stamp_s
        self._emitted_pose = self.pose
        self._emitted_stamp_s = stamp_s
        return OdometryIncrement(
            robot_id=self.robot_id,
            stamp=stamp_s,
            start_stamp=start_stamp_s,
            dx=float(dx),
            dy=float(dy),
            dtheta=float(dtheta),
        )
