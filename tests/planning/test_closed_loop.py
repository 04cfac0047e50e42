"""Closed-loop acceptance in the simulator: true map and true poses, no SLAM.

Each control period (0.1 s = 5 simulator steps) :func:`drive` takes every robot's true
pose, replans A* on the true costmap every ``replan_period_s``, takes the lookahead
point (eq. 4.67), runs the local planner for all robots jointly and steps the simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from acslam.config import (
    CameraConfig,
    CostmapConfig,
    LidarConfig,
    PlanningConfig,
    RobotsConfig,
    SensorsConfig,
    SimConfig,
)
from acslam.errors import NoPathError
from acslam.grid import GridSpec
from acslam.mapping.costmap import compute_costmap
from acslam.messages import VelocityCommand
from acslam.planning.astar import lookahead_point, plan_path, remaining_length_m
from acslam.planning.dwa import DynamicWindowPlanner
from acslam.planning.fgp import FactorGraphPlanner
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.params import AstarParams, DwaParams, FgpParams
from acslam.planning.recovery import Recovery, penalize
from acslam.planning.stuck import StuckDetector
from acslam.sim.simulator import Simulator
from acslam.worlds.mapio import world_cells
from acslam.worlds.world import World

ROBOTS = RobotsConfig()
PLANNING = PlanningConfig()
ASTAR = AstarParams()
SIM = SimConfig()
# No sensor is read (the planners get the truth): fire none within the runs.
SENSORS = SensorsConfig(lidar=LidarConfig(rate_hz=1e-3), camera=CameraConfig(rate_hz=1e-3))
RES_M = 0.05
GOAL_TOLERANCE_M = 0.2


@dataclass(frozen=True)
class Run:
    """Outcome of one closed-loop run."""

    trajectories: np.ndarray  # (T, R, 3) true poses every simulator step, start included
    collisions: np.ndarray  # (R, 2) contacts: walls, robots
    arrival_s: list[float | None]  # first time within GOAL_TOLERANCE_M of the goal
    final_distance_m: np.ndarray  # (R,) distance to the goal at the end
    stuck_events: int

    @property
    def min_separation_m(self) -> float:
        xy = self.trajectories[:, :, :2]
        gaps = np.linalg.norm(xy[:, :, None] - xy[:, None], axis=-1)
        count = xy.shape[1]
        return float(gaps[:, ~np.eye(count, dtype=bool)].min()) if count > 1 else math.inf


def make_world(
    name: str, width_m: float, height_m: float, free: list[tuple[float, float, float, float]]
) -> World:
    """Walls everywhere except the given free rectangles ``(x0, y0, x1, y1)`` (m)."""
    spec = GridSpec(0.0, 0.0, RES_M, round(height_m / RES_M), round(width_m / RES_M))
    centres = spec.cell_to_world(np.argwhere(np.ones(spec.shape, dtype=bool)))
    x, y = centres[:, 0].reshape(spec.shape), centres[:, 1].reshape(spec.shape)
    occupied = np.ones(spec.shape, dtype=bool)
    for x0, y0, x1, y1 in free:
        occupied &= ~((x > x0) & (x < x1) & (y > y0) & (y < y1))
    return World(name, spec, occupied)


def drive(
    world: World,
    starts: list[tuple[float, float, float]],
    goals: list[tuple[float, float]],
    planner: str,
    seconds: float,
    *,
    global_path: bool = True,
    recovery: bool = False,
    seed: int = 0,
) -> Run:
    """Run the team for ``seconds`` with the ``"fgp"`` or ``"dwa"`` local planner.

    ``global_path=False`` gives the local planner the goal itself as lookahead point
    (the local planner alone, as with a map that does not show the obstacle yet) until a
    recovery asks for a replan; from then on that robot follows A* paths.
    """
    spec = world.spec
    costmap = compute_costmap(world_cells(world), spec, CostmapConfig(), ROBOTS.radius_m)
    # The distance field is to cell centres, the simulator's walls are cell squares:
    # half a cell diagonal off makes the planners' clearance a lower bound of the truth.
    field = DistanceField(np.maximum(costmap.distance_m - RES_M / math.sqrt(2.0), 0.0), spec)
    sim = Simulator(world, np.array(starts), np.zeros((0, 3)), ROBOTS, SENSORS, SIM, seed)
    goals_m = [np.array(g, dtype=float) for g in goals]
    count = len(starts)
    fgp = FactorGraphPlanner(FgpParams(), planning=PLANNING, robots=ROBOTS)
    dwa = DynamicWindowPlanner(DwaParams(), planning=PLANNING, robots=ROBOTS)
    recoveries = [Recovery(PLANNING) for _ in range(count)]
    follow_path = [global_path] * count
    paths: list[np.ndarray] = [np.array([s[:2], g]) for s, g in zip(starts, goals_m, strict=True)]
    planned_s = [-math.inf] * count
    velocities = [(0.0, 0.0)] * count
    arrival: list[float | None] = [None] * count
    substeps = round(PLANNING.control_period_s / SIM.dt_s)
    reach_m = PLANNING.horizon_s * ROBOTS.max_v_mps

    def replan(r: int, xy_m: np.ndarray, now_s: float) -> None:
        cost = penalize(costmap.cost, spec, recoveries[r].traps_xy_m, PLANNING)
        try:
            path = plan_path(
                cost,
                costmap.lethal,
                spec,
                xy_m,
                goals_m[r],
                cost_weight=ASTAR.cost_weight,
                max_snap_m=ASTAR.max_snap_m,
                shortcut=ASTAR.shortcut,
            )
        except NoPathError:
            return  # keep the previous path
        paths[r] = np.vstack([xy_m, path.points_m])
        planned_s[r] = now_s

    for _ in range(round(seconds / PLANNING.control_period_s)):
        now_s = sim.time_s
        poses = sim.ground_truth.poses()
        states = [RobotState(*pose, *vel) for pose, vel in zip(poses, velocities, strict=True)]
        overrides: dict[int, tuple[float, float]] = {}
        lookahead = []
        for r, state in enumerate(states):
            if arrival[r] is None and np.linalg.norm(state.xy_m - goals_m[r]) < GOAL_TOLERANCE_M:
                arrival[r] = now_s
            if recovery and arrival[r] is None:
                step = recoveries[r].step(now_s, state, remaining_length_m(paths[r], state.xy_m))
                if step.command is not None:
                    overrides[r] = step.command
                if step.replan:
                    follow_path[r] = True
                    planned_s[r] = -math.inf
                    fgp.reset(r)
            if follow_path[r] and now_s - planned_s[r] >= PLANNING.replan_period_s:
                replan(r, state.xy_m, now_s)
            lookahead.append(lookahead_point(paths[r], state.xy_m, reach_m))
        if planner == "fgp":
            commands = fgp.plan(states, lookahead, field)
        else:
            headings = poses[:, 2]
            moving = np.array([v for v, _ in velocities])
            others_v = np.stack([moving * np.cos(headings), moving * np.sin(headings)], axis=1)
            commands = []
            for r, state in enumerate(states):
                others = np.arange(count) != r
                commands.append(
                    dwa.command(state, lookahead[r], field, poses[others, :2], others_v[others])
                )
        commands = [overrides.get(r, c) for r, c in enumerate(commands)]
        sim.step([VelocityCommand(r, now_s, v, w) for r, (v, w) in enumerate(commands)])
        for _ in range(substeps - 1):
            sim.step()
        velocities = [(float(v), float(w)) for v, w in commands]
    gt = sim.ground_truth
    trajectories = np.stack([gt.trajectory(r)[:, 1:] for r in range(count)], axis=1)
    final = np.linalg.norm(gt.poses()[:, :2] - np.array(goals_m), axis=1)
    return Run(trajectories, gt.collisions, arrival, final, sum(rec.count for rec in recoveries))


def assert_safe_and_arrived(run: Run) -> None:
    assert (run.collisions == 0).all(), run.collisions
    assert run.min_separation_m >= 2.0 * ROBOTS.radius_m
    assert all(t is not None for t in run.arrival_s), run.arrival_s
    assert (run.final_distance_m < GOAL_TOLERANCE_M).all(), run.final_distance_m


def corridor_world() -> World:
    """A 6 m long, 1.2 m wide corridor with a 1 m long, 0.6 m deep passing bay."""
    return make_world("corridor", 6.6, 2.2, [(0.3, 0.3, 6.3, 1.5), (2.8, 1.5, 3.8, 2.1)])


def test_two_robots_swap_ends_of_a_corridor_with_fgp() -> None:
    starts = [(0.7, 0.9, 0.0), (5.9, 0.9, math.pi)]
    goals = [(5.9, 0.9), (0.7, 0.9)]
    run = drive(corridor_world(), starts, goals, "fgp", 40.0)
    print(f"corridor: min separation {run.min_separation_m:.3f} m, arrival {run.arrival_s}")
    assert_safe_and_arrived(run)


def crossing() -> tuple[World, list[tuple[float, float, float]], list[tuple[float, float]]]:
    """Four robots on a 1.5 m circle in a 5 m room, each going to the opposite point."""
    world = make_world("room", 5.0, 5.0, [(0.1, 0.1, 4.9, 4.9)])
    angles = np.pi / 2 * np.arange(4)
    starts = [(2.5 + 1.5 * math.cos(a), 2.5 + 1.5 * math.sin(a), a + math.pi) for a in angles]
    goals = [(5.0 - x, 5.0 - y) for x, y, _ in starts]
    return world, starts, goals


def test_four_robots_cross_through_a_common_point_with_fgp() -> None:
    world, starts, goals = crossing()
    run = drive(world, starts, goals, "fgp", 40.0)
    print(f"crossing: min separation {run.min_separation_m:.3f} m, arrival {run.arrival_s}")
    assert_safe_and_arrived(run)


def u_trap_world() -> World:
    """A 6 x 4 m room with a U open toward the robot between it and its goal."""
    spec_free = [(0.1, 0.1, 5.9, 3.9)]
    world = make_world("u-trap", 6.0, 4.0, spec_free)
    centres = world.spec.cell_to_world(np.argwhere(np.ones(world.spec.shape, dtype=bool)))
    x = centres[:, 0].reshape(world.spec.shape)
    y = centres[:, 1].reshape(world.spec.shape)
    back = (x > 3.0) & (x < 3.15) & (y > 1.15) & (y < 2.85)
    arms = (x > 2.2) & (x < 3.15) & (((y > 1.15) & (y < 1.3)) | ((y > 2.7) & (y < 2.85)))
    return World("u-trap", world.spec, world.occupied | back | arms)


U_START = [(1.0, 2.0, 0.0)]
U_GOAL = [(5.0, 2.0)]


def test_dwa_alone_stalls_in_the_u() -> None:
    """Steering at the goal with no global path, DWA drives into the pocket and stays."""
    run = drive(u_trap_world(), U_START, U_GOAL, "dwa", 30.0, global_path=False)
    end = run.trajectories[-1, 0]
    print(f"DWA alone at the U: ends at {end.round(2)}, {run.final_distance_m[0]:.2f} m to go")
    assert run.arrival_s == [None]
    assert 2.2 < end[0] < 3.0 and 1.3 < end[1] < 2.7  # inside the pocket
    assert (run.collisions == 0).all()
    detector = StuckDetector(PLANNING.stuck_timeout_s, PLANNING.stuck_min_progress_m)
    period = round(PLANNING.control_period_s / SIM.dt_s)
    to_go = np.linalg.norm(run.trajectories[::period, 0, :2] - U_GOAL[0], axis=1)
    events = [detector.update(k * PLANNING.control_period_s, d) for k, d in enumerate(to_go)]
    assert detector.count >= 1
    first = next(e for e in events if e is not None)
    print(f"DWA alone: stuck detector fires at {first.stamp_s:.1f} s, {detector.count} events")


def test_fgp_with_recovery_gets_out_of_the_u() -> None:
    run = drive(u_trap_world(), U_START, U_GOAL, "fgp", 60.0, global_path=False, recovery=True)
    print(f"FGP + recovery at the U: arrival {run.arrival_s}, stuck events {run.stuck_events}")
    assert run.stuck_events >= 1
    assert_safe_and_arrived(run)


def test_same_seed_gives_identical_trajectories() -> None:
    world, starts, goals = crossing()
    first = drive(world, starts, goals, "fgp", 8.0, seed=7)
    second = drive(world, starts, goals, "fgp", 8.0, seed=7)
    np.testing.assert_array_equal(first.trajectories, second.trajectories)
    assert np.ptp(first.trajectories[:, :, :2], axis=0).max() > 0.5  # they did move
