"""Dynamic Window Approach local planner (thesis §4.8, eqs. 4.48-4.56).

Differences from the thesis text, on purpose:

* The admissible window (4.48) is reachable within one control period
  (``control_period_s``), not within ``T_p``: the command is re-chosen every period, so
  that is the velocity change the robot can actually make before the next choice.
* Each candidate ``(v, omega)`` is rolled out on the exact constant-velocity arc of eq.
  4.49 and sampled every half cell over ``T_p``; a trajectory is rejected if any sample
  comes closer than the robot radius to an obstacle (distance field) or closer than two
  radii to another robot's constant-velocity prediction. Eq. 4.50 only looks at the end
  point, which would let a trajectory jump over a thin wall.
* ``f_progress`` is ``1 - d_p / d`` (the left-hand form of 4.52; the right-hand form
  rewards moving away), heading uses the predicted pose, and the clearance terms (4.54,
  4.55) use the smallest distance along the trajectory and are zero beyond ``d_max``.
* If every candidate collides, the robot brakes as hard as it can along its current arc,
  which the previous cycle found free for ``T_p`` (far longer than the braking time).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import KW_ONLY, dataclass

import numpy as np

from acslam.config import PlanningConfig, RobotsConfig
from acslam.geometry import wrap_angles
from acslam.pipeline.stages import Commands, Team, Xy
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.params import DwaParams


def _clearance_term(distance_m: np.ndarray, influence_m: float) -> np.ndarray:
    """Eqs. 4.54-4.55: ``-(1 - d / d_max)`` inside the influence range, 0 beyond."""
    return -np.clip(1.0 - distance_m / influence_m, 0.0, None)


def rollout_arcs(
    state: RobotState, v_mps: np.ndarray, omega_radps: np.ndarray, times_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Exact diff-drive poses for constant ``(v, omega)``: positions (S, K, 2), headings (S, K)."""
    v = np.asarray(v_mps, dtype=float)[:, None]
    w = np.asarray(omega_radps, dtype=float)[:, None]
    t = np.asarray(times_s, dtype=float)[None, :]
    theta = state.theta_rad + w * t
    turning = np.abs(w) > 1e-9
    w_safe = np.where(turning, w, 1.0)
    s0, c0 = math.sin(state.theta_rad), math.cos(state.theta_rad)
    dx = np.where(turning, v / w_safe * (np.sin(theta) - s0), v * t * c0)
    dy = np.where(turning, -v / w_safe * (np.cos(theta) - c0), v * t * s0)
    return np.stack([state.x_m + dx, state.y_m + dy], axis=-1), theta


@dataclass(frozen=True)
class DynamicWindowPlanner:
    """Scores sampled ``(v, omega)`` in the dynamic window and returns the best (4.56).

    Each robot plans alone; the others enter as constant-velocity predictions, so the
    planner keeps no state between cycles.
    """

    params: DwaParams
    _: KW_ONLY
    planning: PlanningConfig
    robots: RobotsConfig

    def plan(self, states: Team, goals_xy_m: Sequence[Xy], field: DistanceField) -> Commands:
        """One command per robot, each chosen with the others as moving obstacles."""
        commands = []
        for k, state in enumerate(states):
            others = [s for j, s in enumerate(states) if j != k]
            xy = np.array([s.xy_m for s in others]).reshape(-1, 2)
            velocity = np.array(
                [[s.v_mps * math.cos(s.theta_rad), s.v_mps * math.sin(s.theta_rad)] for s in others]
            ).reshape(-1, 2)
            commands.append(self.command(state, goals_xy_m[k], field, xy, velocity))
        return commands

    def reset(self, robot_id: int) -> None:
        """DWA keeps nothing between cycles."""

    def window(self, v_now_mps: float, omega_now_radps: float) -> tuple[float, ...]:
        """``(v_lo, v_hi, omega_lo, omega_hi)`` reachable within one control period.

        Forward speeds only (``v_min = 0``: no rear sensing). If the current velocity lies
        outside the limits, the window is the one value closest to them.
        """
        dt = self.planning.control_period_s
        dv = self.robots.max_acc_v_mps2 * dt
        dw = self.robots.max_acc_omega_radps2 * dt
        v_lo, v_hi = max(0.0, v_now_mps - dv), min(self.robots.max_v_mps, v_now_mps + dv)
        if v_lo > v_hi:
            v_lo = v_hi = v_now_mps + dv if v_now_mps < 0.0 else v_now_mps - dv
        w_max = self.robots.max_omega_radps
        w_lo, w_hi = max(-w_max, omega_now_radps - dw), min(w_max, omega_now_radps + dw)
        if w_lo > w_hi:
            w_lo = w_hi = omega_now_radps + dw if omega_now_radps < -w_max else omega_now_radps - dw
        return v_lo, v_hi, w_lo, w_hi

    def _candidates(self, state: RobotState) -> tuple[np.ndarray, np.ndarray]:
        v_lo, v_hi, w_lo, w_hi = self.window(state.v_mps, state.omega_radps)
        vs = np.linspace(v_lo, v_hi, self.params.v_samples)
        ws = np.linspace(w_lo, w_hi, self.params.omega_samples)
        extra_w = [w for w in (0.0, state.omega_radps) if w_lo <= w <= w_hi]
        ws = np.unique(np.concatenate([ws, extra_w]))
        v_grid, w_grid = np.meshgrid(vs, ws, indexing="ij")
        return v_grid.ravel(), w_grid.ravel()

    def command(
        self,
        state: RobotState,
        goal_xy_m: np.ndarray,
        field: DistanceField,
        others_xy_m: np.ndarray | None = None,
        others_velocity_mps: np.ndarray | None = None,
    ) -> tuple[float, float]:
        """Best ``(v, omega)`` toward ``goal_xy_m`` (the lookahead point, eq. 4.67).

        ``others_xy_m`` (M, 2) and ``others_velocity_mps`` (M, 2) describe the other
        robots, predicted at constant velocity over the horizon.
        """
        p, weights = self.planning, self.params
        radius = self.robots.radius_m
        v, w = self._candidates(state)
        reach_m = self.robots.max_v_mps * p.horizon_s
        steps = max(weights.min_rollout_steps, math.ceil(reach_m / (0.5 * field.grid.resolution_m)))
        times = np.linspace(p.horizon_s / steps, p.horizon_s, steps)
        xy, theta = rollout_arcs(state, v, w, times)

        clearance = field.value(xy).min(axis=1)
        clearance_now = float(field.value(state.xy_m))
        collides = clearance < min(radius, clearance_now) - 1e-9
        robot_term = np.zeros(len(v))
        if others_xy_m is not None and len(others_xy_m):
            velocity = (
                np.zeros_like(others_xy_m) if others_velocity_mps is None else others_velocity_mps
            )
            predicted = others_xy_m[:, None, :] + velocity[:, None, :] * times[None, :, None]
            gaps = np.linalg.norm(xy[:, None, :, :] - predicted[None], axis=-1).min(axis=(1, 2))
            gap_now = float(np.linalg.norm(others_xy_m - state.xy_m, axis=1).min())
            collides |= gaps < min(2.0 * radius, gap_now) - 1e-9
            robot_term = _clearance_term(gaps, p.robot_influence_m)

        goal = np.asarray(goal_xy_m, dtype=float)
        d_now = float(np.linalg.norm(goal - state.xy_m))
        end = xy[:, -1, :]
        d_end = np.linalg.norm(goal - end, axis=1)
        progress = 1.0 - d_end / max(d_now, 1e-6)
        bearing = np.arctan2(goal[1] - end[:, 1], goal[0] - end[:, 0])
        heading_error = np.abs(wrap_angles(bearing - theta[:, -1]))
        heading = np.where(d_end > 1e-6, 1.0 - heading_error / np.pi, 1.0)
        score = (
            weights.weight_progress * progress
            + weights.weight_heading * heading
            + weights.weight_costmap * _clearance_term(clearance, p.obstacle_influence_m)
            + weights.weight_robot * robot_term
        )
        if collides.all():
            v_lo, _, w_lo, w_hi = self.window(state.v_mps, state.omega_radps)
            return v_lo, min(max(state.omega_radps, w_lo), w_hi)
        best = int(np.argmax(np.where(collides, -np.inf, score)))
        return float(v[best]), float(w[best])
