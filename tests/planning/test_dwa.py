"""DWA: analytic expectations in free space, walls, other robots and the window."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from acslam.config import PlanningConfig, RobotsConfig
from acslam.grid import GridSpec
from acslam.planning.dwa import DynamicWindowPlanner, rollout_arcs
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.params import DwaParams
from acslam.sim.kinematics import limit_command, step_pose

ROBOTS = RobotsConfig()
PLANNING = PlanningConfig()
GRID = GridSpec(-3.0, -3.0, 0.05, 120, 120)


def field_of(occupied: np.ndarray) -> DistanceField:
    return DistanceField(ndimage.distance_transform_edt(~occupied) * GRID.resolution_m, GRID)


FREE = DistanceField(np.full(GRID.shape, 10.0), GRID)


def test_free_space_goal_ahead_reaches_max_speed_straight() -> None:
    dwa = DynamicWindowPlanner(DwaParams(), planning=PLANNING, robots=ROBOTS)
    state = RobotState(0.0, 0.0, 0.0)
    for _ in range(10):
        v, omega = dwa.command(state, np.array([5.0, 0.0]), FREE)
        state = RobotState(0.0, 0.0, 0.0, v, omega)
    assert state.v_mps == pytest.approx(ROBOTS.max_v_mps)
    assert state.omega_radps == pytest.approx(0.0, abs=1e-12)


def test_goal_behind_turns_toward_it() -> None:
    dwa = DynamicWindowPlanner(DwaParams(), planning=PLANNING, robots=ROBOTS)
    pose, vel = (0.0, 0.0, 0.0), (0.0, 0.0)
    goal = np.array([-1.0, 0.3])  # behind, slightly to the left
    v, omega = dwa.command(RobotState(*pose, *vel), goal, FREE)
    assert omega > 0.0
    best_error = math.pi
    for _ in range(80):
        v, omega = dwa.command(RobotState(*pose, *vel), goal, FREE)
        for _ in range(5):
            vel = limit_command(v, omega, *vel, ROBOTS, 0.02)
            pose = step_pose(*pose, *vel, 0.02)
        bearing = math.atan2(goal[1] - pose[1], goal[0] - pose[0])
        error = abs((bearing - pose[2] + math.pi) % (2 * math.pi) - math.pi)
        best_error = min(best_error, error)
    assert best_error < 0.2
    assert math.dist(pose[:2], goal) < math.hypot(*goal) - 0.5


def test_wall_ahead_at_full_speed_is_never_hit() -> None:
    occupied = np.zeros(GRID.shape, dtype=bool)
    occupied[:, GRID.world_to_cell([[0.4, 0.0]])[0, 1] :] = True  # wall from x = 0.4 m
    field = field_of(occupied)
    dwa = DynamicWindowPlanner(DwaParams(), planning=PLANNING, robots=ROBOTS)
    times = np.linspace(0.01, PLANNING.horizon_s, 200)
    pose, vel = (0.0, 0.0, 0.0), (ROBOTS.max_v_mps, 0.0)
    for _ in range(100):
        state = RobotState(*pose, *vel)
        v, omega = dwa.command(state, np.array([2.0, 0.0]), field)
        arc, _ = rollout_arcs(state, np.array([v]), np.array([omega]), times)
        assert field.value(arc[0]).min() >= ROBOTS.radius_m - 1e-9
        for _ in range(5):
            vel = limit_command(v, omega, *vel, ROBOTS, 0.02)
            pose = step_pose(*pose, *vel, 0.02)
            assert float(field.value(np.array(pose[:2]))) > ROBOTS.radius_m


def test_other_robot_ahead_is_not_hit() -> None:
    """Safety only: DWA may stop in front of it (the local minimum of thesis §4.8)."""
    dwa = DynamicWindowPlanner(DwaParams(), planning=PLANNING, robots=ROBOTS)
    other = np.array([[0.6, 0.0]])
    pose, vel = (0.0, 0.0, 0.0), (ROBOTS.max_v_mps, 0.0)
    for _ in range(100):
        v, omega = dwa.command(RobotState(*pose, *vel), np.array([2.0, 0.0]), FREE, other)
        for _ in range(5):
            vel = limit_command(v, omega, *vel, ROBOTS, 0.02)
            pose = step_pose(*pose, *vel, 0.02)
            assert math.dist(pose[:2], other[0]) > 2 * ROBOTS.radius_m


def test_command_stays_in_the_acceleration_window() -> None:
    dwa = DynamicWindowPlanner(DwaParams(), planning=PLANNING, robots=ROBOTS)
    rng = np.random.default_rng(1)
    dv = ROBOTS.max_acc_v_mps2 * PLANNING.control_period_s
    dw = ROBOTS.max_acc_omega_radps2 * PLANNING.control_period_s
    assert dwa.window(0.1, 0.5) == pytest.approx((0.1 - dv, 0.1 + dv, 0.5 - dw, 0.5 + dw))
    assert dwa.window(0.0, 2.84)[0:2] == pytest.approx((0.0, dv))
    assert dwa.window(0.0, 2.84)[3] == pytest.approx(ROBOTS.max_omega_radps)
    for _ in range(50):
        v0 = rng.uniform(0.0, ROBOTS.max_v_mps)
        w0 = rng.uniform(-ROBOTS.max_omega_radps, ROBOTS.max_omega_radps)
        state = RobotState(0.0, 0.0, rng.uniform(-math.pi, math.pi), v0, w0)
        v, omega = dwa.command(state, rng.uniform(-2.0, 2.0, 2), FREE)
        assert abs(v - v0) <= dv + 1e-12 and 0.0 <= v <= ROBOTS.max_v_mps
        assert abs(omega - w0) <= dw + 1e-12 and abs(omega) <= ROBOTS.max_omega_radps
