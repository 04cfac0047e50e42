"""The team map's OccupancyGrid values, re-classified only where the map changed, equal a
classification of the whole grid after any sequence of added and moved scans."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.mapping.occupancy import FusedGrids, TeamMap, grid_spec_for_bounds
from acslam.mapping.params import SubmapMappingConfig
from acslam.mapping.submaps import SubmapTeamMap

CONFIG = SubmapMappingConfig(max_range_m=3.0, submap_travel_m=0.5, submap_max_scans=6)
SPEC = grid_spec_for_bounds(-6.0, -6.0, 6.0, 6.0, 0.05)
ANGLES = np.linspace(-np.pi, np.pi, 72, endpoint=False)


@pytest.mark.parametrize("mapper", [TeamMap, SubmapTeamMap])
def test_values_follow_every_added_and_moved_scan(mapper: type[FusedGrids]) -> None:
    rng = np.random.default_rng(5)
    team = mapper(CONFIG, spec=SPEC)
    poses: dict[int, np.ndarray] = {}
    reads = 0
    for index in range(60):
        robot_id = index % 3
        ranges = rng.uniform(0.3, 2.5, 72)
        ranges[rng.random(72) < 0.1] = np.inf
        pose = np.array([-2.0 + 0.08 * (index // 3), -2.0 + 2.0 * robot_id, rng.uniform(-1, 1)])
        team.add_scan(robot_id, index, ranges, ANGLES, pose, 3.5)
        poses[index] = pose
        if index % 5 == 4:
            # A correction of earlier scans (submap anchors among them), up to 0.3 m and
            # 0.2 rad: far enough that whole walls change cells.
            for moved in rng.choice(index + 1, size=4, replace=False):
                poses[int(moved)] = poses[int(moved)] + rng.normal(0.0, [0.1, 0.1, 0.07])
                team.move_scan(int(moved), poses[int(moved)])
        if index % 3 == 2:
            got = team.occupancy_values()
            assert np.array_equal(got, team.global_grid.to_occupancy_values())
            assert not got.flags.writeable
            reads += 1
    assert reads == 20
    # Reading twice without a change gives the same array.
    assert team.occupancy_values() is team.occupancy_values()
