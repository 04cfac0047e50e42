"""Joint multi-robot factor-graph local planner, FGP (thesis §4.8, eqs. 4.57-4.71).

One GTSAM graph per control cycle holds every robot's states ``[x, y, vx, vy]`` at steps
``0..N`` (``dt = T_p / N``), keyed ``robot * (N + 1) + step``:

* start prior (4.59): tight on the measured position, ``fgp_start_sigma_mps`` on the
  current velocity (the velocity may change by about one acceleration step);
* constant-velocity dynamics (4.60-4.62): linear, so a C++ ``JacobianFactor`` wrapped in
  a ``LinearContainerFactor`` linearised at zero (no Python callback);
* goal prior (4.68) on the last position at the lookahead point, ``fgp_goal_sigma_m``;
  the last velocity is left almost free (sigma 10 m/s);
* obstacle factors (4.63-4.64), ``e = max(0, 1 - d / d_max^obs)`` with ``d`` the
  bilinearly interpolated distance field, and inter-robot factors (4.65-4.66),
  ``e = max(0, 1 - |p_r - p_s| / d_max^robot)``, both ``gtsam.CustomFactor``. They are
  added for steps ``1..N`` (step 0 is fixed by the start prior) whose initial guess lies
  within twice the influence range; beyond ``d_max`` their error and Jacobian are zero.

Solved with Levenberg-Marquardt, warm-started from the previous cycle's solution shifted
by one step and translated onto the measured position. A symmetric head-on meeting is a
saddle of eq. 4.69 where both robots would just stop, so when building the initial guess
a robot that has another one dead ahead is nudged ``fgp_keep_right_m`` to its right.

Commands (4.70-4.71): ``v = |p_1 - p_0| / dt``; the heading to reach is the direction of
``p_1 - p_0`` (toward the goal when that displacement is negligible, unchanged within one
robot radius of the goal) and ``omega = wrap(heading - theta) / dt`` with ``theta`` the
measured heading, which is what ``atan2(vy_0, vx_0)`` means for a diff-drive robot
and stays defined at rest. ``v`` is scaled by ``max(0, cos(heading error))`` so the
robot turns before it drives sideways, then both are clipped to the speed and
acceleration limits.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from acslam.config import PlanningConfig, RobotsConfig
from acslam.planning.field import DistanceField, RobotState

_FREE_VELOCITY_SIGMA_MPS = 10.0


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def obstacle_error(
    state: np.ndarray, field: DistanceField, influence_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4.63 for one state: error (1,) and its Jacobian (1, 4)."""
    distance, gradient = field.value_and_gradient(state[:2])
    jacobian = np.zeros((1, 4))
    if distance >= influence_m:
        return np.zeros(1), jacobian
    jacobian[0, :2] = -gradient / influence_m
    return np.array([1.0 - distance / influence_m]), jacobian


def robot_error(
    state_r: np.ndarray, state_s: np.ndarray, influence_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 4.65 for two states at one step: error (1,), Jacobians (1, 4) for r and s."""
    delta = state_r[:2] - state_s[:2]
    distance = float(np.hypot(delta[0], delta[1]))
    jac_r = np.zeros((1, 4))
    if distance >= influence_m:
        return np.zeros(1), jac_r, jac_r.copy()
    unit = delta / distance if distance > 1e-9 else np.array([1.0, 0.0])
    jac_r[0, :2] = -unit / influence_m
    return np.array([1.0 - distance / influence_m]), jac_r, -jac_r


@dataclass(frozen=True)
class FgpResult:
    """Commands ``(v, omega)`` per robot, the optimised trajectories (R, N+1, 4), cost."""

    commands: list[tuple[float, float]]
    trajectories: np.ndarray
    final_error: float


class FactorGraphPlanner:
    """Receding-horizon joint planner; keeps each robot's last solution for warm starts."""

    def __init__(self, planning: PlanningConfig, robots: RobotsConfig) -> None:
        self.planning = planning
        self.robots = robots
        self.steps = planning.horizon_steps
        self.dt_s = planning.horizon_s / planning.horizon_steps
        self._previous: dict[int, np.ndarray] = {}
        p = planning
        self._start_noise = gtsam.noiseModel.Diagonal.Sigmas(
            np.array([p.fgp_start_sigma_m] * 2 + [p.fgp_start_sigma_mps] * 2)
        )
        self._dynamics_noise = gtsam.noiseModel.Diagonal.Sigmas(
            np.array([p.fgp_dynamics_sigma_m] * 2 + [p.fgp_dynamics_sigma_mps] * 2)
        )
        self._goal_noise = gtsam.noiseModel.Diagonal.Sigmas(
            np.array([p.fgp_goal_sigma_m] * 2 + [_FREE_VELOCITY_SIGMA_MPS] * 2)
        )
        self._obstacle_noise = gtsam.noiseModel.Isotropic.Sigma(1, p.fgp_obstacle_sigma)
        self._robot_noise = gtsam.noiseModel.Isotropic.Sigma(1, p.fgp_robot_sigma)
        a_prev = -np.eye(4)
        a_prev[0, 2] = a_prev[1, 3] = -self.dt_s
        self._dynamics_jacobians = (a_prev, np.eye(4))

    def reset(self, robot_id: int | None = None) -> None:
        """Forget the warm start of one robot (e.g. after a new assignment) or of all."""
        if robot_id is None:
            self._previous.clear()
        else:
            self._previous.pop(robot_id, None)

    def _key(self, robot: int, step: int) -> int:
        return robot * (self.steps + 1) + step

    def _initial_guess(self, robot_id: int, state: RobotState, goal: np.ndarray) -> np.ndarray:
        p0 = state.xy_m
        previous = self._previous.get(robot_id)
        if previous is not None:
            last = previous[-1].copy()
            last[:2] += last[2:] * self.dt_s
            guess = np.vstack([previous[1:], last])
            guess[:, :2] += p0 - guess[0, :2]
        else:
            velocity = (goal - p0) / self.planning.horizon_s
            speed = float(np.linalg.norm(velocity))
            if speed > self.robots.max_v_mps:
                velocity *= self.robots.max_v_mps / speed
            times = np.arange(self.steps + 1)[:, None] * self.dt_s
            guess = np.hstack([p0 + velocity * times, np.tile(velocity, (self.steps + 1, 1))])
        guess[0, 2:] = state.v_mps * np.array(
            [math.cos(state.theta_rad), math.sin(state.theta_rad)]
        )
        return guess

    def _keep_right(self, guesses: np.ndarray, goals: np.ndarray) -> None:
        """Nudge states that have another robot dead ahead to the right (in place)."""
        nudge = self.planning.fgp_keep_right_m
        radius = self.robots.radius_m
        original = guesses.copy()
        for r in range(len(guesses)):
            for i in range(1, self.steps + 1):
                forward = goals[r] - original[r, 0, :2]
                norm = float(np.linalg.norm(forward))
                if norm < 1e-6:
                    continue
                forward /= norm
                for s in range(len(guesses)):
                    rel = original[s, i, :2] - original[r, i, :2]
                    ahead = float(rel @ forward)
                    lateral = float(forward[0] * rel[1] - forward[1] * rel[0])
                    close = float(np.linalg.norm(rel)) < 2.0 * self.planning.robot_influence_m
                    if s != r and close and ahead > 0.0 and abs(lateral) < 2.0 * radius:
                        guesses[r, i, :2] += nudge * np.array([forward[1], -forward[0]])
                        break

    def plan(
        self,
        states: Sequence[RobotState],
        goals_xy_m: Sequence[np.ndarray],
        field: DistanceField,
        robot_ids: Sequence[int] | None = None,
    ) -> FgpResult:
        """One control cycle for the whole team: joint solve, then ``(v, omega)`` each.

        ``goals_xy_m`` are the lookahead points (eq. 4.67); ``robot_ids`` (default
        ``0..R-1``) key the warm starts.
        """
        ids = list(range(len(states))) if robot_ids is None else list(robot_ids)
        goals = np.array([np.asarray(g, dtype=float) for g in goals_xy_m]).reshape(-1, 2)
        guesses = np.array(
            [self._initial_guess(k, s, g) for k, s, g in zip(ids, states, goals, strict=True)]
        )
        self._keep_right(guesses, goals)
        graph, values = self._build(states, goals, guesses, field)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.planning.fgp_max_iterations)
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        trajectories = np.array(
            [
                [result.atVector(self._key(r, i)) for i in range(self.steps + 1)]
                for r in range(len(states))
            ]
        )
        for k, trajectory in zip(ids, trajectories, strict=True):
            self._previous[k] = trajectory
        commands = [
            self._command(s, t, g) for s, t, g in zip(states, trajectories, goals, strict=True)
        ]
        return FgpResult(commands, trajectories, graph.error(result))

    def _build(
        self,
        states: Sequence[RobotState],
        goals: np.ndarray,
        guesses: np.ndarray,
        field: DistanceField,
    ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        p = self.planning
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        zero = gtsam.Values()
        a_prev, a_next = self._dynamics_jacobians
        for r, state in enumerate(states):
            start = guesses[r, 0].copy()
            start[:2] = state.xy_m
            graph.add(gtsam.PriorFactorVector(self._key(r, 0), start, self._start_noise))
            goal = np.concatenate([goals[r], np.zeros(2)])
            graph.add(gtsam.PriorFactorVector(self._key(r, self.steps), goal, self._goal_noise))
            for i in range(self.steps + 1):
                values.insert(self._key(r, i), guesses[r, i])
                zero.insert(self._key(r, i), np.zeros(4))
            for i in range(self.steps):
                linear = gtsam.JacobianFactor(
                    self._key(r, i),
                    a_prev,
                    self._key(r, i + 1),
                    a_next,
                    np.zeros(4),
                    self._dynamics_noise,
                )
                graph.add(gtsam.LinearContainerFactor(linear, zero))
            clearance = field.value(guesses[r, 1:, :2])
            for i in np.flatnonzero(clearance < 2.0 * p.obstacle_influence_m) + 1:
                graph.add(self._obstacle_factor(self._key(r, int(i)), field))
        for r in range(len(states)):
            for s in range(r + 1, len(states)):
                gaps = np.linalg.norm(guesses[r, 1:, :2] - guesses[s, 1:, :2], axis=1)
                for i in np.flatnonzero(gaps < 2.0 * p.robot_influence_m) + 1:
                    graph.add(self._robot_factor(self._key(r, int(i)), self._key(s, int(i))))
        return graph, values

    def _obstacle_factor(self, key: int, field: DistanceField) -> gtsam.CustomFactor:
        influence_m = self.planning.obstacle_influence_m

        def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None):
            e, jacobian = obstacle_error(values.atVector(this.keys()[0]), field, influence_m)
            if jacobians is not None:
                jacobians[0] = jacobian
            return e

        return gtsam.CustomFactor(self._obstacle_noise, [key], error)

    def _robot_factor(self, key_r: int, key_s: int) -> gtsam.CustomFactor:
        influence_m = self.planning.robot_influence_m

        def error(this: gtsam.CustomFactor, values: gtsam.Values, jacobians: list | None):
            keys = this.keys()
            e, jac_r, jac_s = robot_error(
                values.atVector(keys[0]), values.atVector(keys[1]), influence_m
            )
            if jacobians is not None:
                jacobians[0] = jac_r
                jacobians[1] = jac_s
            return e

        return gtsam.CustomFactor(self._robot_noise, [key_r, key_s], error)

    def _command(
        self, state: RobotState, trajectory: np.ndarray, goal: np.ndarray
    ) -> tuple[float, float]:
        """Eqs. 4.70-4.71 with the heading rule and limits of the module docstring."""
        displacement = trajectory[1, :2] - trajectory[0, :2]
        step_m = float(np.linalg.norm(displacement))
        to_goal = goal - state.xy_m
        if float(np.linalg.norm(to_goal)) <= self.robots.radius_m:
            heading = state.theta_rad
        elif step_m > 0.05 * self.robots.max_v_mps * self.dt_s:
            heading = math.atan2(displacement[1], displacement[0])
        else:
            heading = math.atan2(to_goal[1], to_goal[0])
        heading_error = _wrap(heading - state.theta_rad)
        v = step_m / self.dt_s * max(0.0, math.cos(heading_error))
        omega = heading_error / self.dt_s
        period = self.planning.control_period_s
        dv = self.robots.max_acc_v_mps2 * period
        dw = self.robots.max_acc_omega_radps2 * period
        v = min(max(v, 0.0, state.v_mps - dv), self.robots.max_v_mps, state.v_mps + dv)
        w_max = self.robots.max_omega_radps
        omega = min(max(omega, -w_max, state.omega_radps - dw), w_max, state.omega_radps + dw)
        return v, omega
