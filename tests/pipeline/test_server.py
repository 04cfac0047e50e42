"""The server hands each stage what the protocol promises: checked with a mapper plugin
that records its calls."""

from __future__ import annotations

from collections.abc import Iterator
from typing import ClassVar, Literal

import numpy as np
import pytest

from acslam.config import MappingConfig, parse_scenario
from acslam.grid import GridSpec
from acslam.mapping.occupancy import TeamMap
from acslam.messages import LidarScan
from acslam.pipeline.registry import MAPPERS
from acslam.pipeline.server import Server


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
