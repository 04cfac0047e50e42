"""Joint multi-robot factor-graph local planner, FGP (thesis §4.8, eqs. 4.57-4.71).

One GTSAM graph per control cycle holds every robot's states ``[x, y, vx, vy]`` at steps
``0..N`` (``dt = T_p / N``), keyed ``robot * (N + 1) + step``:

* start prior (4.59): tight on the measured position, ``start_sigma_mps`` on the
  current velocity (the velocity may change by about one acceleration step);
* constant-velocity dynamics (4.60-4.62), linear;
* goal prior (4.68) on the last position at the lookahead point, ``goal_sigma_m``;
  the last velocity is left almost free (sigma 10 m/s);
* obstacle factors (4.63-4.64), ``e = max(0, 1 - d / d_max^obs)`` with ``d`` the
  bilinearly interpolated distance field, and inter-robot factors (4.65-4.66),
  ``e = max(0, 1 - |p_r - p_s| / d_max^robot)`` between robots at the same step, for
  steps ``1..N`` (step 0 is fixed by the start prior).

Speed: GTSAM's ``CustomFactor`` calls back into Python once per factor and iteration,
which cost 77 ms per cycle for 8 robots. Instead we run Levenberg-Marquardt ourselves
(GTSAM's schedule: lambda x10 on a rejected step, /10 on an accepted one, but from 1e-3;
stop when an accepted step lowers the cost by less than 1e-3 of it, or after
``max_iterations`` linear solves; against 1e-5 for both, measured on
``benchmarks/planning_speed.py``, this halves the solves for 3 robots and changes no
closed-loop test outcome). Each iteration evaluates every residual and Jacobian at once
in NumPy (:func:`obstacle_errors`, :func:`robot_errors`) and hands GTSAM one
``GaussianFactorGraph`` of whitened ``JacobianFactor`` s, eliminated in C++ in a fixed
step-major ordering. The hinge factors enter the linear graph only where their error is
positive at the current linearisation point, the tightest possible gating: beyond
``d_max`` their error and Jacobian are zero, and a step that runs into a new one raises
the cost and is rejected.

Warm-started from the previous cycle's solution shifted by one step and translated onto
the measured position. A symmetric head-on meeting is a saddle of eq. 4.69 where both
robots would just stop, so when building the initial guess a robot that has another one
dead ahead is nudged ``keep_right_m`` to its right.

Commands (4.70-4.71): ``v = |p_1 - p_0| / dt``; the heading to reach is the direction of
``p_1 - p_0`` (when that displacement is negligible: unchanged within one robot radius
of the goal, else toward the goal) and ``omega = wrap(heading - theta) / dt`` with
``theta`` the measured heading, which is what ``atan2(vy_0, vx_0)`` means for a
diff-drive robot and stays defined at rest. ``v`` is scaled by ``max(0, cos(heading
error))`` so the robot turns before it drives sideways, then both are clipped to the
speed and acceleration limits.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from acslam.config import PlanningConfig, RobotsConfig
from acslam.geometry import wrap_angle
from acslam.pipeline.stages import Commands, Team, Xy
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.params import FgpParams

_FREE_VELOCITY_SIGMA_MPS = 10.0
_LAMBDA_INITIAL = 1e-3
_LAMBDA_FACTOR = 10.0
_LAMBDA_MAX = 1e5
_LAMBDA_MIN = 1e-10
_RELATIVE_TOLERANCE = 1e-3
_ABSOLUTE_TOLERANCE = 1e-5


def _hinge(distance_m: np.ndarray, influence_m: float) -> np.ndarray:
    """Eqs. 4.63 and 4.65: ``1 - d / d_max`` within the influence, 0 beyond."""
    return np.where(distance_m < influence_m, 1.0 - distance_m / influence_m, 0.0)


@functools.cache
def _robot_pairs(count: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(first, second)`` of every pair of ``count`` robots, ``first < second``
    (``np.triu_indices(count, 1)``, which costs more than the residuals it indexes, made
    once per team size)."""
    first, second = np.triu_indices(count, 1)
    first.flags.writeable = second.flags.writeable = False
    return first, second


def _robot_offsets(xy_r_m: np.ndarray, xy_s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 2) offsets of ``xy_r`` from ``xy_s`` and their (M,) lengths."""
    delta = np.asarray(xy_r_m, dtype=float) - np.asarray(xy_s_m, dtype=float)
    return delta, np.hypot(delta[:, 0], delta[:, 1])


def obstacle_errors(
    xy_m: np.ndarray, field: DistanceField, influence_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4.63 at (M, 2) positions: errors (M,) and their Jacobians (M, 2) w.r.t. ``xy``."""
    distance, gradient = field.value_and_gradient(xy_m)
    inside = distance < influence_m
    return _hinge(distance, influence_m), np.where(inside[:, None], -gradient / influence_m, 0.0)


def robot_errors(
    xy_r_m: np.ndarray, xy_s_m: np.ndarray, influence_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4.65 for (M, 2) position pairs: errors (M,) and Jacobians (M, 2) w.r.t. ``xy_r``.

    The Jacobian w.r.t. ``xy_s`` is the negative. Coincident robots are pushed apart
    along +x rather than getting an undefined direction.
    """
    delta, distance = _robot_offsets(xy_r_m, xy_s_m)
    inside = distance < influence_m
    apart = distance > 1e-9
    unit = np.where(apart[:, None], delta / np.where(apart, distance, 1.0)[:, None], [1.0, 0.0])
    return _hinge(distance, influence_m), np.where(inside[:, None], -unit / influence_m, 0.0)


@dataclass(frozen=True)
class FgpResult:
    """Commands ``(v, omega)`` per robot, the optimised trajectories (R, N+1, 4), the
    final cost (half the sum of squared whitened errors) and the linear solves used."""

    commands: list[tuple[float, float]]
    trajectories: np.ndarray
    final_error: float
    iterations: int


@dataclass(frozen=True)
class FgpProblem:
    """What one cycle optimises: start states (R, 4), goal positions (R, 2), the field."""

    starts: np.ndarray
    goals_xy_m: np.ndarray
    field: DistanceField


class FactorGraphPlanner:
    """Receding-horizon joint planner; keeps each robot's last solution for warm starts."""

    def __init__(
        self, params: FgpParams, *, planning: PlanningConfig, robots: RobotsConfig
    ) -> None:
        self.params = params
        self.planning = planning
        self.robots = robots
        self.steps = params.horizon_steps
        self.dt_s = planning.horizon_s / params.horizon_steps
        self._previous: dict[int, np.ndarray] = {}
        p = params
        # Whitening: residuals and Jacobians are divided by their sigmas in NumPy, so
        # every JacobianFactor carries a unit noise model.
        self._start_sigma = np.array([p.start_sigma_m] * 2 + [p.start_sigma_mps] * 2)
        self._dynamics_sigma = np.array([p.dynamics_sigma_m] * 2 + [p.dynamics_sigma_mps] * 2)
        self._goal_sigma = np.array([p.goal_sigma_m] * 2 + [_FREE_VELOCITY_SIGMA_MPS] * 2)
        # x_{i+1} = F x_i: position advances by velocity * dt, velocity is constant.
        self._transition = np.eye(4)
        self._transition[0, 2] = self._transition[1, 3] = self.dt_s
        self._jac_prev = -self._transition / self._dynamics_sigma[:, None]
        self._jac_next = np.diag(1.0 / self._dynamics_sigma)
        self._jac_start = np.diag(1.0 / self._start_sigma)
        self._jac_goal = np.diag(1.0 / self._goal_sigma)
        self._unit = {k: gtsam.noiseModel.Unit.Create(k) for k in (1, 4)}

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
        count = len(guesses)
        if count < 2:
            return
        forward = goals - guesses[:, 0, :2]
        norm = np.linalg.norm(forward, axis=1)
        moving = norm >= 1e-6
        forward = forward / np.where(moving, norm, 1.0)[:, None]
        # rel[r, s, i]: where robot s is at step i, seen from robot r.
        rel = guesses[None, :, 1:, :2] - guesses[:, None, 1:, :2]
        ahead = np.einsum("rsik,rk->rsi", rel, forward)
        lateral = forward[:, None, None, 0] * rel[..., 1] - forward[:, None, None, 1] * rel[..., 0]
        close = np.linalg.norm(rel, axis=-1) < 2.0 * self.planning.robot_influence_m
        other = ~np.eye(count, dtype=bool)[:, :, None]
        blocked = (
            other & close & (ahead > 0.0) & (np.abs(lateral) < 2.0 * self.robots.radius_m)
        ).any(axis=1) & moving[:, None]
        right = np.stack([forward[:, 1], -forward[:, 0]], axis=1)
        guesses[:, 1:, :2] += self.params.keep_right_m * blocked[..., None] * right[:, None]

    def plan(self, states: Team, goals_xy_m: Sequence[Xy], field: DistanceField) -> Commands:
        """``(v, omega)`` per robot (:meth:`solve` for the trajectories too)."""
        return self.solve(states, goals_xy_m, field).commands

    def solve(
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
        starts = guesses[:, 0].copy()
        starts[:, :2] = [s.xy_m for s in states]
        problem = FgpProblem(starts, goals, field)
        trajectories, cost, iterations = self.optimize(problem, guesses)
        for k, trajectory in zip(ids, trajectories, strict=True):
            self._previous[k] = trajectory
        commands = [
            self._command(s, t, g) for s, t, g in zip(states, trajectories, goals, strict=True)
        ]
        return FgpResult(commands, trajectories, cost, iterations)

    def residuals(self, problem: FgpProblem, x: np.ndarray) -> list[np.ndarray]:
        """Whitened residuals of every factor at states ``x`` (R, N+1, 4), by kind. The
        hinge factors' Jacobians are left out: the cost of every trial step needs only
        their errors."""
        p = self.planning
        positions = x[:, 1:, :2]
        first, second = _robot_pairs(len(x))
        obstacle = _hinge(problem.field.value(positions.reshape(-1, 2)), p.obstacle_influence_m)
        _, gaps_m = _robot_offsets(
            positions[first].reshape(-1, 2), positions[second].reshape(-1, 2)
        )
        return [
            *self._linear_residuals(problem, x),
            obstacle / self.params.obstacle_sigma,
            _hinge(gaps_m, p.robot_influence_m) / self.params.robot_sigma,
        ]

    def _linear_residuals(self, problem: FgpProblem, x: np.ndarray) -> list[np.ndarray]:
        """Whitened residuals of the start, dynamics and goal factors at states ``x``."""
        goal = np.concatenate([problem.goals_xy_m, np.zeros_like(problem.goals_xy_m)], axis=1)
        return [
            (x[:, 0] - problem.starts) / self._start_sigma,
            (x[:, 1:] - x[:, :-1] @ self._transition.T) / self._dynamics_sigma,
            (x[:, -1] - goal) / self._goal_sigma,
        ]

    def cost(self, problem: FgpProblem, x: np.ndarray) -> float:
        """Eq. 4.69: half the sum of squared whitened errors at states ``x``."""
        return 0.5 * sum(float(np.sum(r * r)) for r in self.residuals(problem, x))

    def linearize(self, problem: FgpProblem, x: np.ndarray) -> gtsam.GaussianFactorGraph:
        """The whole team's problem linearised at ``x``, in the update ``delta`` per key.

        Every factor becomes ``J delta = -e`` (whitened), one ``JacobianFactor`` each.
        """
        p = self.planning
        count, n = len(x), self.steps
        start_e, dynamics_e, goal_e = self._linear_residuals(problem, x)
        graph = gtsam.GaussianFactorGraph()
        unit1, unit4 = self._unit[1], self._unit[4]
        for r in range(count):
            graph.add(gtsam.JacobianFactor(self._key(r, 0), self._jac_start, -start_e[r], unit4))
            for i in range(n):
                graph.add(
                    gtsam.JacobianFactor(
                        self._key(r, i),
                        self._jac_prev,
                        self._key(r, i + 1),
                        self._jac_next,
                        -dynamics_e[r, i],
                        unit4,
                    )
                )
            graph.add(gtsam.JacobianFactor(self._key(r, n), self._jac_goal, -goal_e[r], unit4))
        positions = x[:, 1:, :2]
        error, jac = obstacle_errors(
            positions.reshape(-1, 2), problem.field, p.obstacle_influence_m
        )
        jac4 = np.zeros((len(error), 1, 4))
        jac4[:, 0, :2] = jac / self.params.obstacle_sigma
        for flat in np.flatnonzero(error > 0.0):
            r, i = divmod(int(flat), n)
            b = np.array([-error[flat] / self.params.obstacle_sigma])
            graph.add(gtsam.JacobianFactor(self._key(r, i + 1), jac4[flat], b, unit1))
        first, second = _robot_pairs(count)
        error, jac = robot_errors(
            positions[first].reshape(-1, 2), positions[second].reshape(-1, 2), p.robot_influence_m
        )
        jac4 = np.zeros((len(error), 1, 4))
        jac4[:, 0, :2] = jac / self.params.robot_sigma
        for flat in np.flatnonzero(error > 0.0):
            pair, i = divmod(int(flat), n)
            b = np.array([-error[flat] / self.params.robot_sigma])
            graph.add(
                gtsam.JacobianFactor(
                    self._key(int(first[pair]), i + 1),
                    jac4[flat],
                    self._key(int(second[pair]), i + 1),
                    -jac4[flat],
                    b,
                    unit1,
                )
            )
        return graph

    def optimize(self, problem: FgpProblem, x0: np.ndarray) -> tuple[np.ndarray, float, int]:
        """Levenberg-Marquardt from ``x0``: (states, final cost, linear solves used).

        Eliminated step by step (all robots at step 0, then step 1, ...): the dynamics
        chain each robot and the inter-robot factors only couple states of one step, so
        the fill-in stays within two steps, and no COLAMD ordering is computed per solve.
        """
        x = x0.copy()
        count = len(x)
        cost = self.cost(problem, x)
        keys = gtsam.KeyVector(range(x.size // 4))
        ordering = gtsam.Ordering()
        for i in range(self.steps + 1):
            for r in range(count):
                ordering.push_back(self._key(r, i))
        zero4, unit4 = np.zeros(4), self._unit[4]
        damping = _LAMBDA_INITIAL
        solves = 0
        new_cost = cost
        while solves < self.params.max_iterations and cost > _ABSOLUTE_TOLERANCE:
            linear = self.linearize(problem, x)
            accepted = False
            while solves < self.params.max_iterations:
                graph = linear.clone()
                block = math.sqrt(damping) * np.eye(4)
                for key in keys:
                    graph.add(gtsam.JacobianFactor(key, block, zero4, unit4))
                candidate = x + graph.optimize(ordering).vector(keys).reshape(x.shape)
                solves += 1
                new_cost = self.cost(problem, candidate)
                if new_cost < cost:
                    accepted = True
                    break
                damping *= _LAMBDA_FACTOR
                if damping > _LAMBDA_MAX:
                    break
            if not accepted:
                break
            converged = cost - new_cost < _RELATIVE_TOLERANCE * cost
            x, cost = candidate, new_cost
            damping = max(damping / _LAMBDA_FACTOR, _LAMBDA_MIN)
            if converged:
                break
        return x, cost, solves

    def _command(
        self, state: RobotState, trajectory: np.ndarray, goal: np.ndarray
    ) -> tuple[float, float]:
        """Eqs. 4.70-4.71 with the heading rule and limits of the module docstring."""
        displacement = trajectory[1, :2] - trajectory[0, :2]
        step_m = float(np.linalg.norm(displacement))
        to_goal = goal - state.xy_m
        if step_m > 0.05 * self.robots.max_v_mps * self.dt_s:
            # Also at the goal: a robot holding its place there is pushed off a wall or
            # out of a teammate's way by the factors, and turns to where it is pushed.
            # Holding its heading and driving the step's length along it took a robot
            # 0.12 m from a wall into it when it faced the wall (random starts in dungeon
            # seed 1, dungeon-40 seed 1 and lab_ipa seed 2, in their first 3 s).
            heading = math.atan2(displacement[1], displacement[0])
        elif float(np.linalg.norm(to_goal)) <= self.robots.radius_m:
            heading = state.theta_rad
        else:
            heading = math.atan2(to_goal[1], to_goal[0])
        heading_error = wrap_angle(heading - state.theta_rad)
        v = step_m / self.dt_s * max(0.0, math.cos(heading_error))
        omega = heading_error / self.dt_s
        period = self.planning.control_period_s
        dv = self.robots.max_acc_v_mps2 * period
        dw = self.robots.max_acc_omega_radps2 * period
        v = min(max(v, 0.0, state.v_mps - dv), self.robots.max_v_mps, state.v_mps + dv)
        w_max = self.robots.max_omega_radps
        omega = min(max(omega, -w_max, state.omega_radps - dw), w_max, state.omega_radps + dw)
        return v, omega
