"""The server hands each stage what the protocol promises: checked with plugins that
record their calls, and a costmap whose capped distances change no local plan."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import ClassVar, Literal

import numpy as np
import pytest

from acslam.config import MappingConfig, ScenarioConfig, SlamConfig, parse_scenario
from acslam.grid import GridSpec
from acslam.mapping.costmap import compute_costmap
from acslam.mapping.occupancy import TeamMap
from acslam.messages import LidarScan
from acslam.pipeline.registry import LOCAL_PLANNERS, LOCALIZERS, MAPPERS
from acslam.pipeline.server import Server, costmap_reach_m
from acslam.planning.field import DistanceField, RobotState
from acslam.slam.localizer import Isam2Localizer


class RecordingParams(MappingConfig):
    name: Literal["recording"] = "recording"  # type: ignore[assignment]


class RecordingMapper(TeamMap):
    """The log-odds map, remembering the sensor range of every scan it was given."""

    made: ClassVar[list[RecordingMapper]] = []

    def __init__(self, params: RecordingParams, *, spec: GridSpec) -> None:
        super().__init__(params, spec=spec)
        self.range_max_m: list[float] = []
        RecordingMapper.made.append(self)

    def add_scan(self, robot_id, scan_key, ranges, angles, pose, range_max_m=np.inf) -> None:
        self.range_max_m.append(range_max_m)
        super().add_scan(robot_id, scan_key, ranges, angles, pose, range_max_m)


@pytest.fixture
def recording_mapper() -> Iterator[None]:
    MAPPERS.register("recording", RecordingParams)(RecordingMapper)
    yield
    MAPPERS.unregister("recording")


def test_the_mapper_gets_each_scans_own_sensor_range(recording_mapper: None) -> None:
    config = parse_scenario(
        {"world": {"generator": "dungeon"}, "algorithms": {"mapper": {"name": "recording"}}},
        "x.yaml",
    )
    spec = GridSpec(-5.0, -5.0, 0.05, 200, 200)
    server = Server(config, np.zeros((1, 3)), spec)
    angles = np.linspace(-1.0, 1.0, 21)
    scan = LidarScan(0, 0.0, angles, np.full(21, 2.0), range_max_m=3.5)
    server.step([scan], 0.0)
    (mapper,) = RecordingMapper.made
    assert mapper.range_max_m == [3.5]


class RecordingLocalizerParams(SlamConfig):
    name: Literal["recording"] = "recording"  # type: ignore[assignment]


class RecordingLocalizer(Isam2Localizer):
    """The iSAM2 localizer, remembering which of its optimizations searched for loops."""

    made: ClassVar[list[RecordingLocalizer]] = []

    def __init__(self, params: RecordingLocalizerParams, **kwargs) -> None:
        super().__init__(params, **kwargs)
        self.loop_searches: list[bool] = []
        RecordingLocalizer.made.append(self)

    def optimize(self, close_loops: bool) -> None:
        self.loop_searches.append(close_loops)
        super().optimize(close_loops)


@pytest.fixture
def recording_localizer() -> Iterator[None]:
    LOCALIZERS.register("recording", RecordingLocalizerParams)(RecordingLocalizer)
    yield
    LOCALIZERS.unregister("recording")


def test_map_updates_and_loop_searches_keep_their_period_in_different_cycles(
    recording_localizer: None,
) -> None:
    """0.1 s cycles, both periods 0.5 s: map updates in cycles 0, 5, 10, ..., loop
    searches in cycles 3, 8, 13, ..., over 300 s (float sums of 0.1 s drift off exact
    tenths by then)."""
    config = parse_scenario(
        {"world": {"generator": "dungeon"}, "algorithms": {"localizer": {"name": "recording"}}},
        "x.yaml",
    )
    server = Server(config, np.zeros((1, 3)), GridSpec(-5.0, -5.0, 0.05, 200, 200))
    map_updates = []
    for cycle in range(3000):
        snapshot = server.step([], cycle * config.algorithms.planning.control_period_s)
        map_updates.append("costmap" in snapshot.timings_s)
    (localizer,) = RecordingLocalizer.made
    cycles = np.arange(3000)
    assert np.array_equal(np.flatnonzero(map_updates), cycles[cycles % 5 == 0])
    assert np.array_equal(np.flatnonzero(localizer.loop_searches), cycles[cycles % 5 == 3])


def _team_commands(
    field: DistanceField, free: np.ndarray, planner_name: str, config: ScenarioConfig
) -> list:
    """Commands of the local planner for 3 robots at seeded random states on ``free``
    cells, with goals on others."""
    rng = np.random.default_rng(0)
    params = LOCAL_PLANNERS.get(planner_name).params()
    planner = LOCAL_PLANNERS.create(
        params, planning=config.algorithms.planning, robots=config.robots
    )
    commands = []
    for _ in range(15):
        cells = free[rng.choice(len(free), 6, replace=False)]
        xy = field.grid.cell_to_world(cells)
        states = [RobotState(*xy[k], rng.uniform(-np.pi, np.pi), 0.1, 0.0) for k in range(3)]
        planner.reset(0), planner.reset(1), planner.reset(2)
        commands.append(planner.plan(states, list(xy[3:]), field))
    return commands


@pytest.mark.parametrize("planner_name", ["fgp", "dwa"])
def test_the_costmap_reach_changes_no_local_plan(planner_name: str) -> None:
    """The server's costmap caps distances at ``costmap_reach_m``: the local planners'
    commands on that field equal those on the uncapped one, in a cluttered room. A reach
    below the obstacle influence changes them (the check can fail)."""
    config = parse_scenario({"world": {"generator": "dungeon"}}, "x.yaml")
    rng = np.random.default_rng(5)
    spec = GridSpec(0.0, 0.0, 0.05, 160, 200)
    values = np.zeros(spec.shape, dtype=np.int8)
    values[[0, -1], :] = values[:, [0, -1]] = 100
    values[rng.random(spec.shape) < 0.002] = 100

    def field(reach_m: float) -> DistanceField:
        costmap = compute_costmap(
            values, spec, config.algorithms.costmap, config.robots.radius_m, reach_m
        )
        clearance_m = np.maximum(costmap.distance_m - spec.resolution_m / math.sqrt(2.0), 0.0)
        return DistanceField(clearance_m, spec)

    exact = field(math.inf)
    free = np.argwhere(exact.distance_m > 0.3)
    uncapped = _team_commands(exact, free, planner_name, config)
    capped = _team_commands(field(costmap_reach_m(config, spec)), free, planner_name, config)
    assert capped == uncapped
    too_short_m = config.algorithms.planning.obstacle_influence_m / 2
    assert _team_commands(field(too_short_m), free, planner_name, config) != uncapped
