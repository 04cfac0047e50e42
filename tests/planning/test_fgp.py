"""FGP: custom-factor Jacobians, head-on swap of two robots, bypass of an obstacle."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from scipy import ndimage

from acslam.config import PlanningConfig, RobotsConfig
from acslam.grid import GridSpec
from acslam.planning.astar import lookahead_point, plan_path
from acslam.planning.fgp import (
    FactorGraphPlanner,
    FgpProblem,
    obstacle_errors,
    robot_errors,
)
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.params import FgpParams
from acslam.sim.kinematics import limit_command, step_pose

ROBOTS = RobotsConfig()
PLANNING = PlanningConfig()


def new_planner() -> FactorGraphPlanner:
    return FactorGraphPlanner(FgpParams(), planning=PLANNING, robots=ROBOTS)


SIM_DT_S = 0.02


def disc_world(center_xy_m: tuple[float, float], radius_m: float) -> tuple[GridSpec, np.ndarray]:
    grid = GridSpec(-3.0, -2.0, 0.05, 80, 120)
    centres = grid.cell_to_world(np.argwhere(np.ones(grid.shape))).reshape(*grid.shape, 2)
    occupied = np.linalg.norm(centres - np.array(center_xy_m), axis=-1) < radius_m
    return grid, ndimage.distance_transform_edt(~occupied) * grid.resolution_m


def numeric_jacobian(fn, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of ``fn`` (M, 2) -> (M,), row by row: (M, 2)."""
    cols = []
    for k in range(x.shape[1]):
        dx = np.zeros_like(x)
        dx[:, k] = h
        cols.append((fn(x + dx) - fn(x - dx)) / (2 * h))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("seed", range(5))
def test_obstacle_jacobian_matches_central_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    grid = GridSpec(0.0, 0.0, 0.05, 40, 40)
    occupied = ndimage.binary_dilation(rng.random(grid.shape) < 0.01, iterations=2)
    field = DistanceField(ndimage.distance_transform_edt(~occupied) * 0.05, grid)
    influence = PLANNING.obstacle_influence_m
    xy = rng.uniform(0.1, 1.9, (200, 2))
    error, jacobian = obstacle_errors(xy, field, influence)
    np.testing.assert_allclose(error, np.maximum(0.0, 1.0 - field.value(xy) / influence))
    numeric = numeric_jacobian(lambda p: obstacle_errors(p, field, influence)[0], xy)
    active = error > 0.0
    assert active.sum() >= 5
    np.testing.assert_allclose(jacobian, numeric, atol=1e-6)


@pytest.mark.parametrize("seed", range(5))
def test_robot_jacobian_matches_central_differences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    influence = PLANNING.robot_influence_m
    a, b = rng.uniform(-0.3, 0.3, (2, 50, 2))
    error, jac_a = robot_errors(a, b, influence)
    np.testing.assert_allclose(
        error, np.maximum(0.0, 1 - np.linalg.norm(a - b, axis=1) / influence)
    )
    assert (error > 0.0).sum() >= 25
    np.testing.assert_allclose(
        jac_a, numeric_jacobian(lambda x: robot_errors(x, b, influence)[0], a), atol=1e-6
    )
    np.testing.assert_allclose(
        -jac_a, numeric_jacobian(lambda x: robot_errors(a, x, influence)[0], b), atol=1e-6
    )


def test_linearised_graph_matches_the_cost_to_first_order() -> None:
    """The JacobianFactors handed to GTSAM carry the right keys, signs and whitening:
    their error at delta = 0 is the cost, their gradient its numeric gradient."""
    rng = np.random.default_rng(3)
    grid, distance = disc_world((0.0, 0.0), 0.3)
    planner = new_planner()
    count, n = 3, FgpParams().horizon_steps
    # Three robots passing close to the disc and to each other.
    x = np.zeros((count, n + 1, 4))
    for r, y0 in enumerate((-0.35, -0.05, 0.3)):
        x[r, :, 0] = np.linspace(-0.5, 0.5, n + 1)
        x[r, :, 1] = y0
    x += rng.normal(scale=0.03, size=x.shape)
    problem = FgpProblem(
        x[:, 0] + rng.normal(scale=0.01, size=(count, 4)),
        rng.uniform(-1.0, 1.0, (count, 2)),
        DistanceField(distance, grid),
    )
    cost = planner.cost(problem, x)
    graph = planner.linearize(problem, x)
    keys = gtsam.KeyVector(range(x.size // 4))
    zero = gtsam.VectorValues()
    for key in keys:
        zero.insert(key, np.zeros(4))
    assert graph.error(zero) == pytest.approx(cost, rel=1e-9)
    assert planner.residuals(problem, x)[3].any() and planner.residuals(problem, x)[4].any()
    h = 1e-6
    numeric = np.zeros(x.size)
    for k in range(x.size):
        dx = np.zeros(x.size)
        dx[k] = h
        numeric[k] = (
            planner.cost(problem, x + dx.reshape(x.shape))
            - planner.cost(problem, x - dx.reshape(x.shape))
        ) / (2 * h)
    np.testing.assert_allclose(graph.gradientAtZero().vector(keys), numeric, rtol=1e-5, atol=1e-4)


def drive(
    planner: FactorGraphPlanner,
    poses: list[tuple[float, float, float]],
    paths: list[np.ndarray],
    field: DistanceField,
    duration_s: float,
) -> np.ndarray:
    """Closed loop: plan every control period, integrate diff-drive in between.

    Returns the (T, R, 3) poses and checks every command against the limits.
    """
    velocities = [(0.0, 0.0)] * len(poses)
    substeps = round(PLANNING.control_period_s / SIM_DT_S)
    dv = ROBOTS.max_acc_v_mps2 * PLANNING.control_period_s
    history = []
    for _ in range(round(duration_s / PLANNING.control_period_s)):
        states = [RobotState(*p, *v) for p, v in zip(poses, velocities, strict=True)]
        lookahead_m = PLANNING.horizon_s * ROBOTS.max_v_mps
        goals = [
            lookahead_point(path, s.xy_m, lookahead_m)
            for path, s in zip(paths, states, strict=True)
        ]
        result = planner.solve(states, goals, field)
        for r, (v, omega) in enumerate(result.commands):
            assert 0.0 <= v <= ROBOTS.max_v_mps and abs(v - velocities[r][0]) <= dv + 1e-12
            assert abs(omega) <= ROBOTS.max_omega_radps
            for _ in range(substeps):
                velocities[r] = limit_command(v, omega, *velocities[r], ROBOTS, SIM_DT_S)
                poses[r] = step_pose(*poses[r], *velocities[r], SIM_DT_S)
            history.append(poses[r])
    return np.array(history).reshape(-1, len(poses), 3)


def hold_place_beside_a_wall(heading_rad: float, duration_s: float = 3.0) -> np.ndarray:
    """A robot without a path holds its place as its goal (as the server plans it), 0.12 m
    from a wall (x < 0) whose obstacle factors push it off; its x at every step."""
    grid = GridSpec(-1.0, -2.0, 0.05, 80, 60)
    x_m = grid.cell_to_world(np.argwhere(np.ones(grid.shape)))[:, 0].reshape(grid.shape)
    field = DistanceField(np.maximum(x_m, 0.0), grid)
    planner = new_planner()
    pose = (ROBOTS.radius_m + 0.12, 0.0, heading_rad)
    velocity = (0.0, 0.0)
    substeps = round(PLANNING.control_period_s / SIM_DT_S)
    xs = [pose[0]]
    for _ in range(round(duration_s / PLANNING.control_period_s)):
        state = RobotState(*pose, *velocity)
        ((v, omega),) = planner.plan([state], [state.xy_m], field)
        for _ in range(substeps):
            velocity = limit_command(v, omega, *velocity, ROBOTS, SIM_DT_S)
            pose = step_pose(*pose, *velocity, SIM_DT_S)
            xs.append(pose[0])
    return np.array(xs)


@pytest.mark.parametrize("heading_rad", [-2.08, math.pi, 2.5, 0.3])
def test_a_robot_holding_its_place_is_pushed_off_a_wall_and_never_into_it(
    heading_rad: float,
) -> None:
    """Whichever way it faces, the robot turns to where the obstacle factors push it and
    drives off the wall: it never comes nearer. Holding its heading and driving the
    push's length along it, a robot facing the wall touched it after 1.5-1.8 s."""
    xs = hold_place_beside_a_wall(heading_rad)
    assert xs.min() >= xs[0] - 1e-9
    assert xs[-1] > xs[0] + 0.05


def test_two_robots_head_on_swap_positions_without_contact() -> None:
    grid = GridSpec(-4.0, -4.0, 0.05, 160, 160)
    field = DistanceField(np.full(grid.shape, 10.0), grid)
    starts = [(-2.0, 0.0, 0.0), (2.0, 0.0, math.pi)]
    goals = [np.array([2.0, 0.0]), np.array([-2.0, 0.0])]
    paths = [np.array([s[:2], g]) for s, g in zip(starts, goals, strict=True)]
    history = drive(new_planner(), list(starts), paths, field, 30.0)
    separation = np.linalg.norm(history[:, 0, :2] - history[:, 1, :2], axis=1)
    assert separation.min() >= 2 * ROBOTS.radius_m
    for r in range(2):
        assert np.linalg.norm(history[-1, r, :2] - goals[r]) < 0.15


def test_single_robot_goes_around_an_obstacle_hugged_by_the_global_path() -> None:
    grid, distance = disc_world((0.0, 0.0), 0.3)
    field = DistanceField(distance, grid)
    lethal = distance < ROBOTS.radius_m + 0.02
    start, goal = np.array([-2.0, 0.0]), np.array([2.0, 0.0])
    # Cost weight 0: the shortest path grazes the lethal band, the FGP must keep clear.
    path = plan_path(
        np.zeros(grid.shape),
        lethal,
        grid,
        start,
        goal,
        cost_weight=0.0,
        max_snap_m=0.2,
        shortcut=True,
    )
    assert float(field.value(path.points_m).min()) < 0.2
    history = drive(new_planner(), [(-2.0, 0.0, 0.0)], [path.points_m], field, 30.0)
    clearance = np.linalg.norm(history[:, 0, :2], axis=1) - 0.3
    assert clearance.min() > ROBOTS.radius_m
    assert np.linalg.norm(history[-1, 0, :2] - goal) < 0.15
