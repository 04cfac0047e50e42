"""EWFD must return exactly the oracle's reachable frontier cells after every update."""

from __future__ import annotations

import math

import numpy as np
import pytest

from acslam.config import DungeonWorld, LidarConfig, MappingConfig
from acslam.exploration.frontiers import (
    EwfdFrontierDetector,
    active_radius_m,
    away_from_robots,
    frontier_mask,
    reachable_free_mask,
    reachable_frontier_cells,
)
from acslam.grid import GridSpec
from acslam.mapping.occupancy import TeamMap
from acslam.sim.lidar import LidarSensor
from acslam.worlds.generators import build_world
from acslam.worlds.world import World


def _as_set(cells: np.ndarray) -> set[tuple[int, int]]:
    return set(map(tuple, np.asarray(cells).reshape(-1, 2).tolist()))


def test_naive_detector_on_a_hand_made_grid() -> None:
    values = np.array(
        [
            [-1, -1, -1, -1],
            [0, 0, 0, 100],
            [0, 0, 0, 0],
            [0, 0, 0, 0],
        ],
        dtype=np.int8,
    )
    expected = np.zeros(values.shape, dtype=bool)
    expected[1, :3] = True
    np.testing.assert_array_equal(frontier_mask(values), expected)
    # A free region walled off from the robot has no reachable frontier.
    values[2, :] = 100
    robot = np.array([[3, 0]])
    assert len(reachable_frontier_cells(values, robot)) == 0
    assert reachable_free_mask(values, robot)[3].all()


@pytest.mark.parametrize(
    ("closed", "split"),
    [
        ([(3, 5), (3, 6)], True),  # two cells side by side: neither alone closes it
        ([(3, 6)], True),  # one cell whose visited neighbours lie on both sides
        ([(1, 2)], False),  # one cell in the open room: the ring goes round it
        ([(1, 1), (1, 2)], False),  # two cells side by side in the open room
    ],
)
def test_ewfd_splits_only_where_removed_cells_close_a_passage(closed, split) -> None:
    """Two rooms joined by a one-cell-high passage two cells long; the room on the right
    still holds unknown cells. Cells turning occupied split off that room (its frontier
    becomes unreachable) exactly when they close the passage."""
    values = np.full((7, 12), 100, dtype=np.int8)
    values[1:6, 1:5] = 0
    values[1:6, 7:11] = 0
    values[3, 5:7] = 0
    values[2:4, 9] = -1
    robot = np.array([[3, 2]])
    det = EwfdFrontierDetector(GridSpec(0.0, 0.0, 0.1, 7, 12), active_radius_m=0.4)
    before = det.update(values, robot)
    assert _as_set(before) == _as_set(reachable_frontier_cells(values, robot))
    assert len(before) > 0
    for cell in closed:
        values[cell] = 100
    got = det.update(values, robot, np.array(closed))
    assert _as_set(got) == _as_set(reachable_frontier_cells(values, robot))
    assert (len(got) == 0) == split
    np.testing.assert_array_equal(det.visited_mask(), reachable_free_mask(values, robot))


def test_ewfd_matches_oracle_on_random_grid_mutations() -> None:
    """Blobs of random cells rewritten near the scan cells: many splits, merges, removals."""
    rng = np.random.default_rng(7)
    updates = 0
    for _ in range(60):
        rows, cols = (int(v) for v in rng.integers(8, 50, 2))
        det = EwfdFrontierDetector(GridSpec(0.0, 0.0, 0.1, rows, cols), active_radius_m=0.4)
        values = np.full((rows, cols), -1, dtype=np.int8)
        free_share = rng.uniform(0.5, 0.9)
        for _ in range(25):
            scans = np.stack([rng.integers(0, rows, 3), rng.integers(0, cols, 3)], axis=1)
            for r, c in scans:
                h = int(rng.integers(1, 5))  # within the 4-cell active radius
                block = values[max(r - h, 0) : r + h + 1, max(c - h, 0) : c + h + 1]
                other = rng.choice(np.array([-1, 100], dtype=np.int8), block.shape)
                block[:] = np.where(rng.random(block.shape) < free_share, 0, other)
            robots = scans[: int(rng.integers(0, 4))]
            if rng.random() < 0.3:  # robots elsewhere than the scans: components dropped
                robots = np.stack([rng.integers(0, rows, 2), rng.integers(0, cols, 2)], axis=1)
            got = det.update(values, robots, scans if rng.random() < 0.8 else None)
            assert _as_set(got) == _as_set(reachable_frontier_cells(values, robots))
            np.testing.assert_array_equal(det.visited_mask(), reachable_free_mask(values, robots))
            updates += 1
    assert updates == 1500


def _free_pose(world: World, rng: np.random.Generator, near_xy: np.ndarray | None) -> np.ndarray:
    """A random pose with 0.15 m clearance, within 1 m of ``near_xy`` when given."""
    while True:
        if near_xy is None:
            xy = rng.uniform([0.0, 0.0], [world.spec.width_m, world.spec.height_m])
        else:
            xy = near_xy + rng.uniform(-1.0, 1.0, 2)
        if world.clearance_at(float(xy[0]), float(xy[1]), 0.2) >= 0.15:
            return np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ewfd_matches_oracle_on_simulated_multi_robot_exploration(seed: int) -> None:
    """Three robots wander a random dungeon, scan with the simulated LiDAR and update the
    team map; occasionally a robot jumps (its old component must be forgotten) or a scan
    is moved as SLAM would (cells change anywhere, so the whole grid is compared)."""
    rng = np.random.default_rng(seed)
    world_cfg = DungeonWorld(
        generator="dungeon", width_m=14.0, height_m=14.0, room_count=6, resolution_m=0.1
    )
    world = build_world(world_cfg, seed)
    lidar = LidarConfig(beams=120, range_max_m=3.0)
    mapping = MappingConfig(resolution_m=0.1, max_range_m=3.0)
    team = TeamMap(mapping, spec=world.spec)
    detector = EwfdFrontierDetector(world.spec, active_radius_m(mapping))
    sensors = [LidarSensor(lidar, world, np.random.default_rng(seed * 10 + k)) for k in range(3)]
    poses = [_free_pose(world, rng, None) for _ in range(3)]
    no_discs = np.zeros((0, 3))
    checked = 0
    for step in range(100):
        scan_cells = []
        for k, sensor in enumerate(sensors):
            jump = rng.random() < 0.05
            poses[k] = _free_pose(world, rng, None if jump else poses[k][:2])
            scan = sensor.scan(k, float(step), tuple(poses[k]), no_discs, -1)
            team.add_scan(k, (k, step), scan.ranges, scan.angles, poses[k], scan.range_max_m)
            scan_cells.append(world.spec.world_to_cell(poses[k][:2])[0])
        moved = step > 3 and rng.random() < 0.15
        if moved:
            key = (int(rng.integers(0, 3)), int(rng.integers(0, step)))
            team.move_scan(key, team.scan_pose(key) + rng.normal(0.0, [0.1, 0.1, 0.05]))
        values = team.global_grid.to_occupancy_values()
        robot_cells = world.spec.world_to_cell(np.array([p[:2] for p in poses]))
        got = detector.update(values, robot_cells, None if moved else np.array(scan_cells))
        assert _as_set(got) == _as_set(reachable_frontier_cells(values, robot_cells))
        checked += 1
    assert checked == 100


def test_frontier_cells_around_a_robot_are_left_out_by_exact_distance() -> None:
    """With a 0.16 m radius, cells 3 cells (0.15 m) from the robot's cell are dropped, those
    4 cells (0.2 m) away and the far cluster kept, and every cell without robots."""
    spec = GridSpec(0.0, 0.0, 0.05, 40, 40)
    robot = np.array([[20, 20]])
    rim = np.array([[17, 20], [20, 23], [16, 20], [20, 24], [23, 20]])
    far = np.array([[5, 5], [5, 6], [6, 5]])
    cells = np.vstack([rim, far])
    kept = away_from_robots(cells, robot, spec, 0.16)
    assert kept.tolist() == [[16, 20], [20, 24], *far.tolist()]
    # Two robots: each drops what lies near it.
    both = away_from_robots(cells, np.array([[20, 20], [5, 5]]), spec, 0.16)
    assert both.tolist() == [[16, 20], [20, 24]]
    assert away_from_robots(cells, np.zeros((0, 2)), spec, 0.16).tolist() == cells.tolist()
