"""A loaded scenario: validated config, its ground-truth world, start poses, landmarks.

The checks that need the world (a start pose inside a wall or off the map, robots that
overlap, more robots than start poses) live here and raise a
:class:`~acslam.errors.ConfigError` naming the field, like the schema checks do.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from acslam.config import ScenarioConfig, load_scenario_config
from acslam.errors import ConfigError
from acslam.seeding import Stream, rng
from acslam.sim.simulator import Simulator
from acslam.text import plural
from acslam.worlds.generators import build_world
from acslam.worlds.landmarks import place_landmarks
from acslam.worlds.limits import check_world_grid
from acslam.worlds.starts import draw_random_starts
from acslam.worlds.world import World

UNKNOWN_STARTS_SUFFIX = "-unknown-starts"
"""Names a scenario (and a sweep's runs of it) run without known relative starts."""


@dataclass(frozen=True, eq=False)
class Scenario:
    """Everything a run needs to start; ``starts`` has one row per robot."""

    config: ScenarioConfig
    source: str
    world: World
    starts: np.ndarray
    landmarks: np.ndarray

    @property
    def robot_count(self) -> int:
        return len(self.starts)

    def simulator(self) -> Simulator:
        """A fresh simulator of this scenario: its world, team, sensors and seed."""
        config = self.config
        return Simulator(
            self.world,
            self.starts,
            self.landmarks,
            config.robots,
            config.sensors,
            config.sim,
            config.seed,
        )

    def with_unknown_starts(self) -> Scenario:
        """The same scenario with the robots' relative starts unknown to the server
        (:mod:`acslam.pipeline.frames`), named so that its results stand apart."""
        robots = self.config.robots.model_copy(update={"relative_starts": "unknown"})
        name = self.config.name
        if not name.endswith(UNKNOWN_STARTS_SUFFIX):
            name += UNKNOWN_STARTS_SUFFIX
        config = self.config.model_copy(update={"robots": robots, "name": name})
        return Scenario(config, self.source, self.world, self.starts, self.landmarks)

    def with_algorithms(
        self, local_planner: str | None = None, allocator: str | None = None
    ) -> Scenario:
        """The same scenario with another local planner and/or allocator, by plugin name
        (:meth:`~acslam.config.AlgorithmsConfig.with_stage` says which fields carry over)."""
        algorithms = self.config.algorithms
        if local_planner is not None:
            algorithms = algorithms.with_stage("local_planner", local_planner)
        if allocator is not None:
            algorithms = algorithms.with_stage("allocator", allocator)
        config = self.config.model_copy(update={"algorithms": algorithms})
        return Scenario(config, self.source, self.world, self.starts, self.landmarks)

    def with_patrol(self, patrol_s: float) -> Scenario:
        """The same scenario, patrolling the explored map for ``patrol_s`` before the run
        ends (:mod:`acslam.exploration.patrol`)."""
        algorithms = self.config.algorithms
        server = algorithms.server.model_copy(update={"patrol_s": patrol_s})
        algorithms = algorithms.model_copy(update={"server": server})
        config = self.config.model_copy(update={"algorithms": algorithms})
        return Scenario(config, self.source, self.world, self.starts, self.landmarks)


def _check_starts(starts: np.ndarray, world: World, radius_m: float, source: str, field: str):
    spec = world.spec
    x_max = spec.origin_x_m + spec.width_m
    y_max = spec.origin_y_m + spec.height_m
    for i, (x, y, _theta) in enumerate(starts):
        where = f"{field}[{i}]"
        if not (spec.origin_x_m <= x < x_max and spec.origin_y_m <= y < y_max):
            raise ConfigError(
                source,
                where,
                f"start pose ({x:g}, {y:g}) lies outside the map "
                f"[{spec.origin_x_m:g}, {x_max:g}) x [{spec.origin_y_m:g}, {y_max:g}) m",
            )
        clearance = world.clearance_at(x, y)
        if clearance < radius_m:
            raise ConfigError(
                source,
                where,
                f"start pose ({x:g}, {y:g}) is in an obstacle or closer to one "
                f"({clearance:.3f} m) than the robot radius ({radius_m:g} m)",
            )
        for j in range(i):
            gap = float(np.hypot(x - starts[j, 0], y - starts[j, 1]))
            if gap < 2 * radius_m:
                raise ConfigError(
                    source,
                    where,
                    f"robot {i} overlaps robot {j}: centres {gap:.3f} m apart, "
                    f"need >= {2 * radius_m:g} m (two radii)",
                )


def build_scenario(
    config: ScenarioConfig, source: str, robots: int | None = None, robots_field: str = "--robots"
) -> Scenario:
    """Check the world's grid against the memory budget, build the world and check the
    team against it.

    ``robots`` overrides ``robots.count`` and picks the first N start poses; an error
    about it names ``robots_field`` (the option or grid field that gave it).
    """
    team = config.robots
    count = robots or team.team_size()
    check_world_grid(config, source, count)
    try:
        world = build_world(config.world, config.seed)
    except ConfigError as exc:
        if exc.source != ConfigError(None, "", "").source:
            raise
        raise ConfigError(source, exc.field, exc.problem) from None
    if team.starts == "random":
        drawn = draw_random_starts(
            world,
            count,
            team.radius_m,
            team.min_start_separation_m,
            rng(config.seed, Stream.STARTS),
        )
        if drawn is None:
            raise ConfigError(
                source,
                "robots.starts",
                f"no {plural(count, 'random start')} {team.min_start_separation_m:g} m apart "
                f"and out of each other's sight fit in world {world.name!r}: lower "
                "robots.min_start_separation_m or the robot count",
            )
        available, field = drawn, "robots.starts (random)"
    elif team.starts is not None:
        available, field = np.array(team.starts, dtype=float), "robots.starts"
    else:
        available, field = world.default_starts, "robots.starts (the world's default starts)"
    if len(available) == 0:
        raise ConfigError(source, "robots.starts", "this world suggests no start poses: give some")
    if count > len(available):
        count_field = robots_field if robots else "robots.count"
        raise ConfigError(
            source,
            count_field,
            f"{plural(count, 'robot')} requested but only "
            f"{plural(len(available), 'start pose')} {'is' if len(available) == 1 else 'are'} "
            "available",
        )
    starts = available[:count]
    _check_starts(starts, world, team.radius_m, source, field)

    reachable = world.reachable_free(starts[0, 0], starts[0, 1], team.radius_m)
    landmarks = place_landmarks(
        world, config.landmarks, rng(config.seed, Stream.LANDMARKS), reachable
    )
    return Scenario(config, source, world, starts, landmarks)


def load_scenario(
    name_or_path: str | Path, robots: int | None = None, seed: int | None = None
) -> Scenario:
    """Load a built-in scenario by name or a YAML file, optionally overriding team and seed."""
    config, source = load_scenario_config(name_or_path)
    if seed is not None:
        config = config.model_copy(update={"seed": seed})
    return build_scenario(config, source, robots)
