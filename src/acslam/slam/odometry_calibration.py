"""Online odometry calibration: each robot's wheel-odometry scale and drift rates, learned
from its verified sequential scan matches and taken out of its increments.

Real odometry errs systematically, not like white noise: a wheel radius off by 1 %
stretches every distance by 1 %, and a gyro (or differential-drive yaw) bias turns the
robot's estimate at a steady rate for tens of seconds, even at standstill (the thesis's
own odometry model, eqs. 4.73-4.75, has both). The graph's odometry factors treat each
keyframe's error as independent, so a systematic error is not averaged away but passed
on: where scan matching is weak (a corridor's axis) or merely as precise as odometry, the
estimate follows it, and on a floor plan the whole map came out rotated by 0.004-0.008
rad or stretched by 0.3 % along its long corridors. Calibrating odometry online is the
usual remedy (Censi et al., "Simultaneous calibration of odometry and sensor
parameters", IEEE T-RO 2013, do it from scan matches in batch); here it is a Kalman
filter, so each update costs the same however long the run.

Model, over the span between two scans of the robot (``T`` seconds, raw odometry ``u``
and scan-matched motion ``z``, both in the first scan's frame, ``e`` the mean heading
over the span):

* turn: ``u_theta = (1 + scale_turn) z_theta + turn_bias_radps T``
* travel along ``e``: ``e . u_xy = (1 + scale_travel) e . z_xy + travel_bias_mps T``

Both are linear in the state ``[scale_travel, travel_bias_mps, scale_turn,
turn_bias_radps]``; the biases follow a random walk, the scales are constants. An update
whose normalised innovation exceeds the gate (a match that verification let through but
odometry contradicts) is skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from acslam.config import SlamConfig
from acslam.geometry import between, compose
from acslam.messages import OdometryIncrement

HISTORY_S = 120.0
"""Raw odometry kept per robot: a match spanning more than this is not used."""

MATCH_FLOOR_M = 0.002
MATCH_FLOOR_RAD = 0.001
"""Least sigma of a match's travel and turn in an update, for odometry's own white noise."""


@dataclass
class OdometryCalibration:
    """One robot's odometry calibration and the raw odometry since ``HISTORY_S`` ago."""

    config: SlamConfig
    mean: np.ndarray = field(default_factory=lambda: np.zeros(4))
    covariance: np.ndarray = field(init=False)
    updates: int = 0
    rejected: int = 0
    _stamps_s: list[float] = field(default_factory=list)
    _poses: list[np.ndarray] = field(default_factory=list)  # raw, composed from the start
    _turns_rad: list[float] = field(default_factory=list)  # raw, summed (unwrapped)
    _last_update_s: float | None = None

    def __post_init__(self) -> None:
        c = self.config
        self.covariance = np.diag(
            [
                c.calibration_scale_prior_std**2,
                c.calibration_travel_bias_prior_std_mps**2,
                c.calibration_scale_prior_std**2,
                c.calibration_turn_bias_prior_std_radps**2,
            ]
        )

    @property
    def scale_travel(self) -> float:
        return float(self.mean[0])

    @property
    def travel_bias_mps(self) -> float:
        return float(self.mean[1])

    @property
    def scale_turn(self) -> float:
        return float(self.mean[2])

    @property
    def turn_bias_radps(self) -> float:
        return float(self.mean[3])

    def correct(self, msg: OdometryIncrement) -> OdometryIncrement:
        """Record the raw increment; return it with the current calibration taken out."""
        duration_s = msg.stamp - msg.start_stamp
        if not self._stamps_s:
            self._stamps_s.append(msg.start_stamp)
            self._poses.append(np.zeros(3))
            self._turns_rad.append(0.0)
        self._stamps_s.append(msg.stamp)
        self._poses.append(compose(self._poses[-1], msg.delta))
        self._turns_rad.append(self._turns_rad[-1] + msg.dtheta)
        if msg.stamp - self._stamps_s[0] > 2.0 * HISTORY_S:
            keep = int(np.searchsorted(self._stamps_s, msg.stamp - HISTORY_S))
            del self._stamps_s[:keep], self._poses[:keep], self._turns_rad[:keep]
        s_travel, b_travel, s_turn, b_turn = self.mean
        dtheta = (msg.dtheta - b_turn * duration_s) / (1.0 + s_turn)
        heading = 0.5 * msg.dtheta
        forward = b_travel * duration_s
        dx = (msg.dx - forward * math.cos(heading)) / (1.0 + s_travel)
        dy = (msg.dy - forward * math.sin(heading)) / (1.0 + s_travel)
        return OdometryIncrement(msg.robot_id, msg.stamp, msg.start_stamp, dx, dy, dtheta)

    def update(
        self, start_s: float, end_s: float, relative: np.ndarray, covariance: np.ndarray
    ) -> bool:
        """Fold in a verified scan match: the sensor moved by ``relative`` (``[x, y,
        theta]`` in its frame at ``start_s``, covariance ``covariance``) by ``end_s``.
        Returns whether it was used."""
        raw = self._raw_between(start_s, end_s)
        if raw is None:
            return False
        u, u_turn = raw
        duration_s = end_s - start_s
        if self._last_update_s is not None and end_s > self._last_update_s:
            walk = self.config
            self.covariance[1, 1] += walk.calibration_travel_bias_walk_mps_per_sqrt_s**2 * (
                end_s - self._last_update_s
            )
            self.covariance[3, 3] += walk.calibration_turn_bias_walk_radps_per_sqrt_s**2 * (
                end_s - self._last_update_s
            )
        self._last_update_s = max(end_s, self._last_update_s or end_s)
        heading = 0.5 * float(relative[2])
        along = np.array([math.cos(heading), math.sin(heading)])
        z_along = float(along @ relative[:2])
        design = np.array([[z_along, duration_s, 0.0, 0.0], [0.0, 0.0, relative[2], duration_s]])
        predicted = np.array([z_along, relative[2]]) + design @ self.mean
        innovation = np.array([along @ u[:2], u_turn]) - predicted
        match_var = np.array(
            [
                float(along @ covariance[:2, :2] @ along) + MATCH_FLOOR_M**2,
                float(covariance[2, 2]) + MATCH_FLOOR_RAD**2,
            ]
        )
        # z enters both sides; its noise, scaled by (1 + scale), is the measurement noise.
        gain_of_z = 1.0 + self.mean[[0, 2]]
        noise = np.diag(match_var * gain_of_z**2)
        noise[0, 1] = noise[1, 0] = float(along @ covariance[:2, 2]) * gain_of_z[0] * gain_of_z[1]
        innovation_cov = design @ self.covariance @ design.T + noise
        if float(innovation @ np.linalg.solve(innovation_cov, innovation)) > (
            self.config.calibration_gate
        ):
            self.rejected += 1
            return False
        gain = np.linalg.solve(innovation_cov, design @ self.covariance).T
        self.mean = self.mean + gain @ innovation
        identity_less_kh = np.eye(4) - gain @ design
        self.covariance = identity_less_kh @ self.covariance @ identity_less_kh.T
        self.covariance += gain @ noise @ gain.T
        self.updates += 1
        return True

    def _raw_between(self, start_s: float, end_s: float) -> tuple[np.ndarray, float] | None:
        """Raw odometry motion (in the frame at ``start_s``) and summed turn over the span,
        or None if the history does not cover it."""
        if not self._stamps_s or start_s < self._stamps_s[0] or end_s > self._stamps_s[-1]:
            return None
        if end_s <= start_s:
            return None
        a_pose, a_turn = self._at(start_s)
        b_pose, b_turn = self._at(end_s)
        return between(a_pose, b_pose), b_turn - a_turn

    def _at(self, stamp_s: float) -> tuple[np.ndarray, float]:
        i = int(np.searchsorted(self._stamps_s, stamp_s))
        if self._stamps_s[i] == stamp_s or i == 0:
            return self._poses[i], self._turns_rad[i]
        t0, t1 = self._stamps_s[i - 1], self._stamps_s[i]
        w = (stamp_s - t0) / (t1 - t0)
        step = between(self._poses[i - 1], self._poses[i])
        turn = self._turns_rad[i - 1] + w * (self._turns_rad[i] - self._turns_rad[i - 1])
        return compose(self._poses[i - 1], w * step), turn

    def summary(self) -> dict[str, float | int]:
        """The estimate and its sigmas, for metrics."""
        sigmas = np.sqrt(np.diag(self.covariance))
        names = ("scale_travel", "travel_bias_mps", "scale_turn", "turn_bias_radps")
        out: dict[str, float | int] = {}
        for name, value, sigma in zip(names, self.mean, sigmas, strict=True):
            out[name] = float(value)
            out[f"{name}_sigma"] = float(sigma)
        out["updates"] = self.updates
        out["rejected"] = self.rejected
        return out
