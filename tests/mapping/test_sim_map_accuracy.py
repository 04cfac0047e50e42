"""Map accuracy in simulation (thesis Table 5.4): 3 robots on scripted routes.

Each robot follows a fixed route (A* on the true map between hand-picked goals, planned
once, then a turn-then-drive waypoint controller on the *true* pose: the test is about the
map, not the planner). The server's SLAM and mapping pieces see only the robots'
messages: odometry, camera landmarks and LiDAR into :class:`SlamBackend` with
:class:`LidarConstraints`, scans into :class:`TeamMap` at their keyframe-relative pose and
moved when SLAM corrects a keyframe, beams ending on another robot dropped, all wired as in
:class:`acslam.pipeline.server.Server`. The global map is scored against the true occupancy over
its known cells with :func:`confusion_rates`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from acslam.config import CostmapConfig
from acslam.eval.metrics import confusion_rates
from acslam.mapping.costmap import compute_costmap
from acslam.mapping.occupancy import TeamMap
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, VelocityCommand
from acslam.planning.astar import plan_path
from acslam.scenario import Scenario, load_scenario
from acslam.sim.simulator import Simulator
from acslam.slam.backend import SlamBackend
from acslam.slam.lidar_constraints import LidarConstraints
from acslam.worlds.mapio import world_cells

CONTROL_PERIOD_S = 0.1
LOOKAHEAD_M = 0.3  # the target is the first path point this far ahead

# Goals per robot, in the order visited (read off `acslam map --scenario NAME`).
ROUTES = {
    "thesis-exp4": [
        [(19.0, 22.5), (19.0, 27.0), (21.0, 22.0), (21.0, 23.7), (25.4, 23.7), (25.4, 26.0)],
        [(14.6, 20.0), (14.6, 25.0), (18.0, 25.0), (19.9, 17.5), (15.4, 17.0), (15.4, 14.4)],
        [(25.6, 20.0), (25.6, 15.3), (23.8, 15.3)],
    ],
    # Each robot closes a loop round a vine row: up one gap, back the next. Along a gap
    # the laser odometry still drifts (a few cm and mrad over 16 m); an open route
    # would keep that drift, a loop closure spreads it out. The robots start in a column
    # in the headland (y = 6.25, 6.85, 5.65): the northern one takes the northern loop,
    # so no two first legs cross (crossing ones met head-on, whichever of the equal-cost
    # paths A* returned).
    "vineyard": [
        [(-1.0, 6.2), (15.5, 6.2), (15.5, 3.8), (-1.0, 3.8), (-1.0, 6.2)],
        [(-1.0, 8.8), (15.5, 8.8), (15.5, 11.3), (-1.0, 11.3), (-1.0, 8.8)],
        [(-1.0, 1.2), (15.5, 1.2), (15.5, -1.3), (-1.0, -1.3), (-1.0, 1.2)],
    ],
}


def _waypoints(scenario: Scenario, goals: list[tuple[float, float]], start: np.ndarray):
    """The cell-by-cell A* path through the goals on the true costmap (kept off walls by
    the cost term, which a shortcut path cutting corners is not)."""
    world = scenario.world
    robots = scenario.config.robots
    costmap = compute_costmap(world_cells(world), world.spec, CostmapConfig(), robots.radius_m)
    astar = scenario.config.algorithms.global_planner
    points, here = [], start[:2]
    for goal in goals:
        path = plan_path(
            costmap.cost, costmap.lethal, world.spec, here, np.array(goal),
            cost_weight=astar.cost_weight, max_snap_m=astar.max_snap_m, shortcut=False,
        )  # fmt: skip
        points.extend(path.points_m[1:])
        here = path.points_m[-1]
    return np.array(points)


def _command(robot_id: int, pose: np.ndarray, target: np.ndarray, stamp: float, v_max: float):
    dx, dy = target - pose[:2]
    error = math.remainder(math.atan2(dy, dx) - pose[2], 2 * math.pi)
    if abs(error) > 0.3:
        return VelocityCommand(robot_id, stamp, 0.0, float(np.clip(1.5 * error, -1.0, 1.0)))
    return VelocityCommand(robot_id, stamp, v_max, float(np.clip(2.0 * error, -1.0, 1.0)))


def _mappable(scan: LidarScan, pose: np.ndarray, others: np.ndarray, reach_m: float):
    """The scan minus invalid readings and beams ending on another robot (as the server)."""
    keep = scan.ranges > 0
    angles = scan.angles + pose[2]
    ends = pose[:2] + scan.ranges[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    for other in others:
        with np.errstate(invalid="ignore"):
            keep &= ~(np.linalg.norm(ends - other[:2], axis=1) < reach_m)
    return scan.angles[keep], scan.ranges[keep]


# The vineyard's fence (10 cm) and plants are thin structures whose far side no beam
# clears: occupied updates only up to 3 m, where the LDS-02's range sigma (5 mm + 1.5 %)
# reaches a 5 cm cell, and the hit kernel on the sensor side (see
# acslam.mapping.occupancy.LogOddsGrid). Not the vineyard scenario's own setting: in an
# exploration run the walls these leave gappy stay frontiers (600 s without finishing).
THIN_STRUCTURE_MAPPING = {"hit_max_range_m": 3.0, "kernel_beyond_hit": False}
MAPPING = {"thesis-exp4": {}, "vineyard": THIN_STRUCTURE_MAPPING}


def map_run(name: str, max_time_s: float) -> tuple[dict[str, float], int]:
    """Drive the scripted routes, map, and score; returns the rates and the scans mapped."""
    scenario = load_scenario(name)
    config, world = scenario.config, scenario.world
    algorithms = config.algorithms
    starts = scenario.starts
    routes = [_waypoints(scenario, goals, s) for goals, s in zip(ROUTES[name], starts, strict=True)]
    sim = Simulator(
        world, starts, scenario.landmarks, config.robots, config.sensors, config.sim, config.seed
    )
    slam = SlamBackend(algorithms.localizer, {i: s for i, s in enumerate(starts)})
    lidar = LidarConstraints(algorithms.scan_matching)
    team = TeamMap(algorithms.mapper.model_copy(update=MAPPING[name]), spec=world.spec)
    reach_m = config.robots.radius_m + algorithms.server.robot_filter_margin_m
    substeps = max(1, round(CONTROL_PERIOD_S / config.sim.dt_s))
    next_target = [0] * len(starts)
    next_map_update_s = 0.0
    while sim.time_s < max_time_s and any(
        k < len(r) for k, r in zip(next_target, routes, strict=True)
    ):
        poses = sim.ground_truth.poses()
        commands = []
        for i, pose in enumerate(poses):
            route = routes[i]
            while next_target[i] < len(route) and (
                np.linalg.norm(route[next_target[i]] - pose[:2]) < LOOKAHEAD_M
            ):
                next_target[i] += 1
            if next_target[i] < len(route):
                commands.append(
                    _command(i, pose, route[next_target[i]], sim.time_s, config.robots.max_v_mps)
                )
            else:
                commands.append(VelocityCommand(i, sim.time_s, 0.0, 0.0))
        messages = sim.step(commands)
        for _ in range(substeps - 1):
            messages += sim.step()
        scans = []
        for message in messages:
            if isinstance(message, OdometryIncrement):
                slam.add_odometry(message)
            elif isinstance(message, LandmarkObservations):
                slam.add_landmarks(message)
            elif isinstance(message, LidarScan):
                index = slam.add_scan(message)
                if index is not None:
                    scans.append((index, message))
        for index, scan in scans:
            lidar.add_scan(slam, index, scan)
        closures = 0
        if sim.time_s >= next_map_update_s:
            closures = lidar.close_loops(slam)
            next_map_update_s = sim.time_s + algorithms.server.map_update_period_s
        slam.update(extra_iterations=2 if closures else 0)
        estimates = np.array([slam.latest_pose(i) for i in range(len(starts))])
        for index, scan in scans:
            pose = slam.scans.pose(index)
            others = np.delete(estimates, scan.robot_id, axis=0)
            angles, ranges = _mappable(scan, pose, others, reach_m)
            team.add_scan(scan.robot_id, index, ranges, angles, pose)
        for index in slam.scans.of_keyframes(slam.moved_keyframes()):
            team.move_scan(index, slam.scans.pose(index))
    assert all(k == len(r) for k, r in zip(next_target, routes, strict=True)), (
        f"routes unfinished at {sim.time_s:.0f} s: waypoint {next_target} of "
        f"{[len(r) for r in routes]}, robots at {sim.ground_truth.poses().round(2).tolist()}, "
        f"routes {[r.round(1).tolist() for r in routes]}"
    )
    values = team.occupancy_values()
    return confusion_rates(world.occupied, values), len(team)


@pytest.mark.parametrize("name", ["thesis-exp4", "vineyard"])
def test_scripted_team_map_is_accurate(name: str) -> None:
    """Thesis Table 5.4 targets: accuracy >= 97 %, TPR >= 85 % over the known cells.

    Measured: thesis-exp4 0.982 / 0.999, vineyard 0.974 / 0.924 (mapped at the true poses
    the vineyard scores 0.982 / 0.993: its remaining false positives are the far side of
    the 10 cm fence, which no beam clears, and the rims of the round plants; with the
    default mapping 0.947 / 0.942, the fence's far side smeared by far returns).
    """
    rates, scans = map_run(name, max_time_s=400.0)
    print(f"{name}: {scans} scans, accuracy {rates['accuracy']:.4f}, TPR {rates['tpr']:.4f}")
    assert rates["accuracy"] >= 0.97
    assert rates["tpr"] >= 0.85
