"""Online odometry calibration: each robot's wheel-odometry scale errors and travel drift,
learned from its verified sequential scan matches and taken out of its increments.

Real odometry errs systematically, not like white noise: a wheel radius off by 1 %
stretches every distance by 1 %, a turn-rate scale error turns every rotation by the same
share, and a speed bias moves a robot that stands still (the thesis's own odometry model,
eqs. 4.73-4.75, has all three, and a turn-rate bias). The graph's odometry factors treat
each keyframe's error as independent, so a systematic error is not averaged away but
passed on: where scan matching is weak (a corridor's axis) or merely as precise as
odometry, the estimate follows it. On the office_c floor plan the map came out stretched
by 0.35 % along its 70 m corridor, and on office_d a robot's heading drifted 0.03 rad.
Calibrating odometry online is the usual remedy (Censi et al., "Simultaneous calibration
of odometry and sensor parameters", IEEE T-RO 2013, do it from scan matches in batch);
here it is a Kalman filter, so each update costs the same however long the run.

Model, over the span between two scans of the robot (``T`` seconds, raw odometry ``u``
and scan-matched motion ``z``, both in the first scan's frame, ``e`` the mean heading
over the span):

* travel along ``e``: ``e . u_xy = (1 + scale_travel) e . z_xy + travel_bias_mps T``
* turn: ``u_theta = (1 + scale_turn) z_theta``, with the turn-rate bias's drift over
  ``T`` counted as noise.

The scales are constants; the travel bias follows a random walk. The turn-rate bias is
not estimated: wandering over tens of seconds, it would be learned from the heading of
the same matches that enter the graph, and the corrected odometry would then repeat the
matches' own random walk instead of checking it. An update whose normalised innovation
exceeds the gate (a match that verification let through but odometry contradicts) is
skipped.
"""

from __future__ import annotations

import bisect
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
"""Sigmas added to a match's travel and turn in an update, for odometry's white noise."""


@dataclass
class OdometryCalibration:
    """One robot's odometry calibration and the raw odometry since ``HISTORY_S`` ago."""

    config: SlamConfig
    mean: np.ndarray = field(default_factory=lambda: np.zeros(3))
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
                c.calibration_travel_bias_std_mps**2,
                c.calibration_scale_prior_std**2,
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

    def correct(self, msg: OdometryIncrement) -> OdometryIncrement:
        """Record the raw increment; return it with the current calibration taken out."""
        if not self._stamps_s:
            self._stamps_s.append(msg.start_stamp)
            self._poses.append(np.zeros(3))
            self._turns_rad.append(0.0)
        self._stamps_s.append(msg.stamp)
        self._poses.append(compose(self._poses[-1], msg.delta))
        self._turns_rad.append(self._turns_rad[-1] + msg.dtheta)
        if msg.stamp - self._stamps_s[0] > 2.0 * HISTORY_S:
            keep = bisect.bisect_left(self._stamps_s, msg.stamp - HISTORY_S)
            del self._stamps_s[:keep], self._poses[:keep], self._turns_rad[:keep]
        scale_travel, travel_bias_mps, scale_turn = self.mean
        heading = 0.5 * msg.dtheta
        forward_m = travel_bias_mps * (msg.stamp - msg.start_stamp)
        dx = (msg.dx - forward_m * math.cos(heading)) / (1.0 + scale_travel)
        dy = (msg.dy - forward_m * math.sin(heading)) / (1.0 + scale_travel)
        return OdometryIncrement(
            msg.robot_id, msg.stamp, msg.start_stamp, dx, dy, msg.dtheta / (1.0 + scale_turn)
        )

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
        c = self.config
        if self._last_update_s is None or end_s > self._last_update_s:
            if self._last_update_s is not None:
                self.covariance[1, 1] += c.calibration_travel_bias_walk_mps_per_sqrt_s**2 * (
                    end_s - self._last_update_s
                )
            self._last_update_s = end_s
        heading = 0.5 * float(relative[2])
        along = np.array([math.cos(heading), math.sin(heading)])
        z = np.array([float(along @ relative[:2]), float(relative[2])])
        design = np.array([[z[0], duration_s, 0.0], [0.0, 0.0, z[1]]])
        predicted = z + design @ self.mean
        innovation = np.array([float(along @ u[:2]), u_turn]) - predicted
        # z enters scaled by (1 + scale); the turn bias's drift over the span is noise.
        gain_of_z = 1.0 + self.mean[[0, 2]]
        noise = np.array(
            [
                [float(along @ covariance[:2, :2] @ along), float(along @ covariance[:2, 2])],
                [float(along @ covariance[:2, 2]), float(covariance[2, 2])],
            ]
        ) * np.outer(gain_of_z, gain_of_z)
        noise += np.diag(
            [
                MATCH_FLOOR_M**2,
                (c.calibration_turn_bias_std_radps * duration_s) ** 2 + MATCH_FLOOR_RAD**2,
            ]
        )
        innovation_cov = design @ self.covariance @ design.T + noise
        if float(innovation @ np.linalg.solve(innovation_cov, innovation)) > c.calibration_gate:
            self.rejected += 1
            return False
        gain = np.linalg.solve(innovation_cov, design @ self.covariance).T
        self.mean = self.mean + gain @ innovation
        identity_less_kh = np.eye(3) - gain @ design
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
        i = bisect.bisect_left(self._stamps_s, stamp_s)
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
        return {
            "scale_travel": self.scale_travel,
            "scale_travel_sigma": float(sigmas[0]),
            "travel_bias_mps": self.travel_bias_mps,
            "travel_bias_mps_sigma": float(sigmas[1]),
            "scale_turn": self.scale_turn,
            "scale_turn_sigma": float(sigmas[2]),
            "updates": self.updates,
            "rejected": self.rejected,
        }
