"""Recovery: fires after the stuck timeout, backs off, asks for a replan, penalises traps."""

from __future__ import annotations

import numpy as np

from acslam.config import PlanningConfig
from acslam.grid import GridSpec
from acslam.planning.field import RobotState
from acslam.planning.recovery import Recovery, penalize

PLANNING = PlanningConfig()
PERIOD_S = PLANNING.control_period_s


def test_stuck_robot_backs_off_then_asks_for_a_replan() -> None:
    recovery = Recovery(PLANNING)
    state = RobotState(1.0, 2.0, 0.0)
    steps = [recovery.step(k * PERIOD_S, state, 3.0) for k in range(101)]
    assert all(s.command is None and not s.replan for s in steps[:-1])
    event = steps[-1].event
    assert event is not None and event.count == 1 and recovery.count == 1
    assert steps[-1].command == (-PLANNING.recovery_back_off_mps, 0.0) and recovery.active
    np.testing.assert_allclose(recovery.traps_xy_m, [[1.0, 2.0]])
    # Reversing along -x until the back-off distance is covered, then a replan.
    x_m, t_s = 1.0, 10.0
    while True:
        t_s += PERIOD_S
        step = recovery.step(t_s, RobotState(x_m, 2.0, 0.0, -0.1), 3.0)
        if step.command is None:
            break
        x_m -= 0.1 * PERIOD_S
    assert step.replan and not recovery.active
    assert 1.0 - x_m >= PLANNING.recovery_back_off_m - 1e-9
    # The detector restarted: no new event before another full timeout.
    later = [recovery.step(t_s + k * PERIOD_S, RobotState(x_m, 2.0, 0.0), 3.2) for k in range(99)]
    assert all(s.event is None for s in later) and recovery.count == 1


def test_blocked_back_off_gives_up_after_twice_its_nominal_time() -> None:
    recovery = Recovery(PLANNING)
    state = RobotState(0.0, 0.0, 0.0)
    for k in range(101):
        recovery.step(k * PERIOD_S, state, 3.0)
    assert recovery.active
    nominal_s = PLANNING.recovery_back_off_m / PLANNING.recovery_back_off_mps
    t_s = 10.0 + 2.0 * nominal_s - 1e-6
    assert recovery.step(t_s, state, 3.0).command is not None
    assert recovery.step(10.0 + 2.0 * nominal_s, state, 3.0).replan


def test_penalty_raises_cost_near_traps_only_and_keeps_lethal() -> None:
    grid = GridSpec(0.0, 0.0, 0.1, 30, 30)
    cost = np.zeros(grid.shape)
    cost[0, 0] = np.inf
    recovery = Recovery(PLANNING)
    np.testing.assert_array_equal(penalize(cost, grid, recovery.traps_xy_m, PLANNING), cost)
    recovery.traps_xy_m.append(np.array([1.5, 1.5]))
    penalised = penalize(cost, grid, recovery.traps_xy_m, PLANNING)
    centres = grid.cell_to_world(np.argwhere(np.ones(grid.shape, dtype=bool))).reshape(30, 30, 2)
    near = np.linalg.norm(centres - [1.5, 1.5], axis=-1) <= PLANNING.recovery_penalty_radius_m
    assert near.sum() > 50
    np.testing.assert_array_equal(penalised[near], PLANNING.recovery_penalty_cost)
    assert np.isinf(penalised[0, 0]) and (penalised[~near & np.isfinite(cost)] == 0.0).all()
    recovery.reset(0.0)
    assert recovery.traps_xy_m == [] and recovery.count == 0


def test_penalty_near_the_grid_edge_equals_measuring_every_cell() -> None:
    """Traps by an edge, off the grid and overlapping: each cell of the grid measured
    against each trap (the brute-force reference) gives the same costs, to the bit."""
    grid = GridSpec(-1.0, 2.0, 0.05, 47, 61)
    rng = np.random.default_rng(3)
    cost = rng.uniform(0.0, 5.0, grid.shape)
    cost[rng.uniform(size=grid.shape) < 0.1] = np.inf
    before = cost.copy()
    traps = [np.array(t) for t in ([-0.95, 2.1], [0.1, 3.0], [0.2, 3.1], [-1.3, 1.8], [5.0, 9.0])]
    centres = grid.cell_to_world(np.argwhere(np.ones(grid.shape, dtype=bool))).reshape(47, 61, 2)
    expected = cost.copy()
    for trap in traps:
        near = np.linalg.norm(centres - trap, axis=-1) <= PLANNING.recovery_penalty_radius_m
        expected[near] += PLANNING.recovery_penalty_cost
    np.testing.assert_array_equal(penalize(cost, grid, traps, PLANNING), expected)
    np.testing.assert_array_equal(cost, before)
    assert (expected != cost).sum() > 100


def test_a_new_goal_forgets_traps_and_the_same_goal_keeps_them() -> None:
    recovery = Recovery(PlanningConfig())
    timeout = PlanningConfig().stuck_timeout_s
    recovery.step(0.0, RobotState(1.0, 1.0, 0.0, 0.0, 0.0), 2.0)
    step = recovery.step(timeout, RobotState(1.0, 1.0, 0.0, 0.0, 0.0), 2.0)
    assert step.event is not None and len(recovery.traps_xy_m) == 1
    recovery.replanned(timeout + 1.0, new_goal=False, distance_to_goal_m=3.0)
    assert len(recovery.traps_xy_m) == 1 and recovery.active
    recovery.replanned(timeout + 2.0, new_goal=True, distance_to_goal_m=3.0)
    assert recovery.traps_xy_m == [] and not recovery.active and recovery.count == 1
