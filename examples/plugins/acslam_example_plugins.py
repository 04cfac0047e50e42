"""Two plugins written outside acslam: a nearest-frontier allocator and a pure-pursuit
local planner.

A plugin is a class with the methods of its stage's protocol
(:mod:`acslam.pipeline.stages`), a pydantic ``Params`` model whose ``name`` is the name it
registers under, and the registry's decorator. A scenario then chooses it by name::

    algorithms:
      allocator: {name: example-nearest}
      local_planner: {name: example-pursuit, turn_gain_per_s: 2.0}

and so does the command line (``acslam run --allocator example-nearest``) once the module
is imported: by an ``acslam.plugins`` entry point of an installed package, e.g. in its
``pyproject.toml``::

    [project.entry-points."acslam.plugins"]
    examples = "acslam_example_plugins"
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from acslam.config import PlanningConfig, PositiveFloat, RobotsConfig, StageParams
from acslam.exploration.allocation import Allocation
from acslam.geometry import wrap_angle
from acslam.mapping.costmap import Costmap
from acslam.pipeline.registry import ALLOCATORS, LOCAL_PLANNERS
from acslam.pipeline.stages import Cells, Clusters, Commands, Goals, Team, Xy
from acslam.planning.field import DistanceField


class NearestParams(StageParams):
    name: Literal["example-nearest"] = "example-nearest"


@ALLOCATORS.register("example-nearest", NearestParams)
class NearestAllocator:
    """Every robot takes the cluster whose target is nearest in a straight line."""

    def __init__(self, params: NearestParams) -> None:
        self.params = params

    def allocate(
        self, robot_cells: Cells, clusters: Clusters, costmap: Costmap, current: Goals = None
    ) -> Allocation:
        robots_m = costmap.spec.cell_to_world(np.asarray(robot_cells).reshape(-1, 2))
        if not clusters:
            return Allocation(self.params.name, "nearest", (None,) * len(robots_m), np.zeros(0))
        targets_m = np.array([c.target_m for c in clusters])
        distances_m = np.linalg.norm(robots_m[:, None] - targets_m[None], axis=2)
        choice = tuple(int(k) for k in np.argmin(distances_m, axis=1))
        return Allocation(self.params.name, "nearest", choice, distances_m)


class PursuitParams(StageParams):
    name: Literal["example-pursuit"] = "example-pursuit"
    turn_gain_per_s: PositiveFloat = 1.5  # omega = gain * heading error


@LOCAL_PLANNERS.register("example-pursuit", PursuitParams)
class PurePursuitPlanner:
    """Turn toward the lookahead point, drive forward as far as the heading allows; the
    robots do not avoid each other, so this planner suits one robot or open spaces."""

    def __init__(
        self, params: PursuitParams, *, planning: PlanningConfig, robots: RobotsConfig
    ) -> None:
        self.params = params
        self.robots = robots

    def plan(self, states: Team, goals_xy_m: Sequence[Xy], field: DistanceField) -> Commands:
        commands = []
        for state, goal in zip(states, goals_xy_m, strict=True):
            to_goal = np.asarray(goal) - state.xy_m
            if float(np.hypot(*to_goal)) < self.robots.radius_m:
                commands.append((0.0, 0.0))
                continue
            error = wrap_angle(math.atan2(to_goal[1], to_goal[0]) - state.theta_rad)
            w_max = self.robots.max_omega_radps
            omega = min(max(self.params.turn_gain_per_s * error, -w_max), w_max)
            commands.append((self.robots.max_v_mps * max(0.0, math.cos(error)), omega))
        return commands

    def reset(self, robot_id: int) -> None:
        """Pure pursuit keeps nothing between cycles."""
