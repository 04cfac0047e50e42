"""Log-odds grid and team map: analytic beam updates, exact pose corrections, a box world."""

from __future__ import annotations

import math

import numpy as np
import pytest

from acslam.config import MappingConfig
from acslam.grid import GridSpec, bresenham
from acslam.mapping.occupancy import (
    FIXED_POINT_SCALE,
    HIT_DEPTH_CELLS,
    LogOddsGrid,
    TeamMap,
    _add_to_grids,
    grid_spec_for_bounds,
)

QUANTUM = 1.0 / FIXED_POINT_SCALE


def _increments_by_cell(grid: LogOddsGrid, ranges, angles, pose) -> dict[tuple[int, int], float]:
    update = grid.scan_update(np.asarray(ranges, float), np.asarray(angles, float), pose)
    rows, cols = np.unravel_index(update.flat_indices, grid.spec.shape)
    return {
        (int(r), int(c)): float(v)
        for r, c, v in zip(rows, cols, update.log_odds_increments(), strict=True)
    }


def test_single_beam_updates_bresenham_cells_with_analytic_values() -> None:
    cfg = MappingConfig(
        resolution_m=0.1,
        delta_free=-0.4,
        delta_occ=0.85,
        distance_alpha_per_m=0.05,
        hit_sigma_m=0.1,
        hit_radius_m=0.1,
    )
    grid = LogOddsGrid(GridSpec(0.0, 0.0, 0.1, 10, 20), cfg)
    # Sensor at the centre of cell (5, 2); a 0.98 m beam along +x ends at x = 1.23 m, and
    # HIT_DEPTH_CELLS (half a cell) deeper still in cell (5, 12).
    got = _increments_by_cell(grid, [0.98], [0.0], [0.25, 0.55, 0.0])

    def falloff(d: float) -> float:
        return 1.0 - 0.05 * d

    kernel_side = 0.85 * math.exp(-0.5)  # one cell (0.1 m) from the endpoint, sigma 0.1 m
    expected = {(5, c): -0.4 * falloff(0.1 * (c - 2)) for c in range(2, 12)}
    expected[(5, 12)] = 0.85 * falloff(1.0)  # endpoint: occupied only (eq. 4.34, weight 1)
    expected[(5, 11)] += kernel_side * falloff(0.9)  # crossed and next to the endpoint
    expected[(5, 13)] = kernel_side * falloff(1.1)
    expected[(4, 12)] = kernel_side * falloff(math.hypot(1.0, 0.1))
    expected[(6, 12)] = kernel_side * falloff(math.hypot(1.0, 0.1))
    assert set(got) == set(expected)
    for cell, value in expected.items():
        assert got[cell] == pytest.approx(value, abs=QUANTUM), cell
    # Hand-computed spot checks of the formulas above.
    assert got[(5, 2)] == pytest.approx(-0.4, abs=QUANTUM)
    assert got[(5, 7)] == pytest.approx(-0.39, abs=QUANTUM)
    assert got[(5, 12)] == pytest.approx(0.8075, abs=QUANTUM)


def test_a_scans_cells_are_its_beams_lines_each_once_in_grid_order() -> None:
    """With a kernel of the endpoint cell alone, a scan changes exactly the cells of its
    beams' Bresenham lines (``grid.bresenham``) that lie in the grid, listed once each
    and in increasing order, also where beams leave the grid."""
    grid = LogOddsGrid(
        GridSpec(0.0, 0.0, 0.1, 80, 60), MappingConfig(resolution_m=0.1, hit_radius_m=0.05)
    )
    rng = np.random.default_rng(0)
    angles = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    ranges = rng.uniform(0.2, 3.0, len(angles))
    pose = np.array([1.05, 4.05, 0.3])  # 1 m from the left edge, 3 m or more from the others
    flat = grid.scan_update(ranges, angles, pose).flat_indices
    assert np.all(np.diff(flat) > 0)
    ((r0, c0),) = grid.spec.world_to_cell(pose[:2])
    lengths_m = ranges + HIT_DEPTH_CELLS * grid.spec.resolution_m
    ends_m = pose[:2] + lengths_m[:, None] * np.stack(
        [np.cos(pose[2] + angles), np.sin(pose[2] + angles)], axis=1
    )
    expected = set()
    for r1, c1 in grid.spec.world_to_cell(ends_m):
        line = bresenham(int(r0), int(c0), int(r1), int(c1))
        inside = grid.spec.contains(line)
        expected |= set((line[inside, 0] * grid.spec.cols + line[inside, 1]).tolist())
    assert any(c < 0 for _, c in grid.spec.world_to_cell(ends_m))  # some beams leave the grid
    assert set(flat.tolist()) == expected


def test_integrate_then_remove_leaves_an_empty_grid() -> None:
    grid = LogOddsGrid(GridSpec(-5.0, -5.0, 0.05, 200, 200), MappingConfig())
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    ranges = np.random.default_rng(0).uniform(0.5, 9.0, 360)
    grid.integrate(ranges, angles, [0.3, -0.2, 0.4])
    assert (grid.to_occupancy_values() == 100).any()
    grid.integrate(ranges, angles, [0.3, -0.2, 0.4], sign=-1)
    assert not grid.accumulator_fixed.any()


@pytest.mark.parametrize("free_on_no_return", [True, False])
def test_no_return_beams_never_mark_occupied(free_on_no_return: bool) -> None:
    cfg = MappingConfig(max_range_m=3.0, free_on_no_return=free_on_no_return)
    grid = LogOddsGrid(GridSpec(-5.0, -5.0, 0.05, 200, 200), cfg)
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    for _ in range(3):
        grid.integrate(np.full(90, np.inf), angles, [0.0, 0.0, 0.0])
    assert (grid.accumulator_fixed <= 0).all()
    values = grid.to_occupancy_values()
    if not free_on_no_return:
        assert not grid.accumulator_fixed.any()
        return
    free_cells = np.argwhere(values == 0)
    centres = grid.spec.cell_to_world(free_cells)
    assert len(free_cells) > 0
    assert np.hypot(centres[:, 0], centres[:, 1]).max() <= 3.0 + grid.spec.resolution_m


def test_far_returns_clear_short_of_the_return_and_mark_nothing() -> None:
    cfg = MappingConfig(hit_max_range_m=2.0, far_free_margin_m=0.23)
    grid = LogOddsGrid(GridSpec(-5.0, -5.0, 0.05, 200, 200), cfg)
    got = _increments_by_cell(grid, [3.0, 1.0], [0.0, math.pi / 2], [0.0, 0.0, 0.0])
    along_x = sorted(c for (r, c), v in got.items() if r == 100 and c >= 100)
    # Cells 100 .. 154 cover x in [0, 2.75): the beam clears up to 3.0 - 0.23 = 2.77 m,
    # its last cell (the end point's, x in [2.75, 2.80)) excluded as for any beam.
    assert along_x == list(range(100, 155))
    assert all(got[(100, c)] < 0 for c in along_x)
    positive = np.array([cell for cell, v in got.items() if v > 0])
    assert np.allclose(grid.spec.cell_to_world(positive)[:, 1], 1.025, atol=0.101)


def _deepest_occupied_update_cells(config: MappingConfig) -> float:
    """Largest offset along the beam, in cells, of a cell with an occupied update beyond
    the endpoint's cell, over 2 m beams at 7 angles."""
    grid = LogOddsGrid(GridSpec(-5.0, -5.0, 0.05, 200, 200), config)
    deepest = -math.inf
    for angle in np.linspace(-np.pi / 3, np.pi / 3, 7):
        sensor = np.array([-2.0 * math.cos(angle), -2.0 * math.sin(angle), angle])
        got = _increments_by_cell(grid, [2.0], [0.0], sensor)
        end = grid.spec.world_to_cell(
            np.array([[0.025 * math.cos(angle), 0.025 * math.sin(angle)]])
        )[0]
        direction = np.array([math.sin(angle), math.cos(angle)])  # (row, col) of the beam
        for (row, col), value in got.items():
            if value > 0:
                deepest = max(deepest, float((np.array([row, col]) - end) @ direction))
    return deepest


def test_hit_kernel_can_stay_on_the_sensor_side_of_the_endpoint() -> None:
    assert _deepest_occupied_update_cells(MappingConfig()) >= 1.0  # eq. 4.34: all round
    assert _deepest_occupied_update_cells(MappingConfig(kernel_beyond_hit=False)) <= 1e-9


def test_beams_beyond_max_range_only_clear() -> None:
    grid = LogOddsGrid(GridSpec(-5.0, -5.0, 0.05, 200, 200), MappingConfig(max_range_m=2.0))
    got = _increments_by_cell(grid, [3.0, 1.0], [0.0, math.pi / 2], [0.0, 0.0, 0.0])
    positive = [cell for cell, v in got.items() if v > 0]
    centres = grid.spec.cell_to_world(np.array(positive))
    # Only the kernel (radius 0.1 m) around the 1 m hit at +y, nothing at the 3 m beam.
    assert np.allclose(centres[:, 0], 0.025, atol=0.101)
    assert np.allclose(centres[:, 1], 1.025, atol=0.101)


def _random_scan(rng: np.random.Generator, beams: int = 90) -> tuple[np.ndarray, np.ndarray]:
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    ranges = rng.uniform(0.2, 5.0, beams)
    ranges[rng.random(beams) < 0.1] = np.inf
    return ranges, angles


def test_random_corrections_equal_integrating_from_scratch() -> None:
    rng = np.random.default_rng(42)
    spec = grid_spec_for_bounds(-6.0, -6.0, 6.0, 6.0, 0.05)
    cfg = MappingConfig(max_range_m=4.0, log_odds_min=-1.0, log_odds_max=1.0)
    team = TeamMap(cfg, spec=spec)
    scans = {}
    for key in range(30):
        robot_id = key % 3
        ranges, angles = _random_scan(rng)
        pose = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        team.add_scan(robot_id, ("scan", key), ranges, angles, pose)
        scans[key] = (robot_id, ranges, angles)
    for move in range(150):
        key = int(rng.integers(30))
        new_pose = team.scan_pose(("scan", key)) + rng.normal(0.0, [0.1, 0.1, 0.05])
        team.move_scan(("scan", key), new_pose)
        if move % 10 == 0:  # read between changes, as the server does
            assert np.array_equal(team.known_mask(), team.global_grid.known_mask())

    fresh = TeamMap(cfg, spec=spec)
    for key, (robot_id, ranges, angles) in scans.items():
        fresh.add_scan(robot_id, ("scan", key), ranges, angles, team.scan_pose(("scan", key)))
    assert np.array_equal(team.global_grid.accumulator_fixed, fresh.global_grid.accumulator_fixed)
    assert np.array_equal(team.global_grid.log_odds(), fresh.global_grid.log_odds())
    assert np.array_equal(team.known_mask(), fresh.global_grid.known_mask())
    for robot_id in range(3):
        assert np.array_equal(
            team.robot_grid(robot_id).accumulator_fixed,
            fresh.robot_grid(robot_id).accumulator_fixed,
        )
    # The global map is exactly the fusion of all robots; a subset is a partial fusion.
    assert np.array_equal(
        team.combined([0, 1, 2]).accumulator_fixed, team.global_grid.accumulator_fixed
    )
    assert team.combined([0]).known_mask().sum() <= team.combined([0, 1]).known_mask().sum()
    # The clamped view really clamps, and removal still ends exactly at zero.
    assert team.global_grid.log_odds().max() == cfg.log_odds_max
    assert team.global_grid.log_odds().min() == cfg.log_odds_min
    for key in scans:
        team.remove_scan(("scan", key))
    assert not team.global_grid.accumulator_fixed.any()
    assert len(team) == 0


def test_team_map_rejects_duplicate_keys() -> None:
    team = TeamMap(MappingConfig(), spec=GridSpec(0.0, 0.0, 0.1, 10, 10))
    team.add_scan(0, "a", [0.3], [0.0], [0.5, 0.5, 0.0])
    with pytest.raises(KeyError):
        team.add_scan(1, "a", [0.3], [0.0], [0.5, 0.5, 0.0])


def _box_ranges(pose: np.ndarray, angles: np.ndarray, low_m: float, high_m: float) -> np.ndarray:
    """Perfect ray caster for the inside of the square [low, high]^2 (walls are its sides)."""
    dx, dy = np.cos(pose[2] + angles), np.sin(pose[2] + angles)
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, high_m - pose[0], low_m - pose[0]) / dx
        ty = np.where(dy > 0, high_m - pose[1], low_m - pose[1]) / dy
    return np.minimum(np.abs(tx), np.abs(ty))


def test_box_world_walls_occupied_interior_free() -> None:
    spec = GridSpec(0.0, 0.0, 0.05, 100, 100)
    grid = LogOddsGrid(spec, MappingConfig())
    low_m, high_m = 0.525, 4.475  # centres of cell rows/cols 10 and 89
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    rng = np.random.default_rng(1)
    for _ in range(10):
        pose = np.array([2.5, 2.5, 0.0]) + rng.uniform(-0.3, 0.3, 3)
        grid.integrate(_box_ranges(pose, angles, low_m, high_m), angles, pose)
    values = grid.to_occupancy_values()
    wall = np.zeros(spec.shape, dtype=bool)
    wall[[10, 89], 10:90] = True
    wall[10:90, [10, 89]] = True
    assert (values[wall] == 100).all()
    assert (values[11:89, 11:89] == 0).all()
    outside = np.ones(spec.shape, dtype=bool)
    outside[7:93, 7:93] = False  # beyond the kernel radius behind the walls
    assert (values[outside] == -1).all()
    assert np.array_equal(grid.known_mask(), values != -1)
    probabilities = grid.probabilities()
    assert (probabilities[wall] >= 0.65).all() and (probabilities[11:89, 11:89] <= 0.35).all()


def test_grid_for_bounds_covers_the_rectangle() -> None:
    grid = LogOddsGrid.for_bounds(-1.0, 2.0, 3.02, 4.0, MappingConfig(resolution_m=0.1))
    assert grid.spec.shape == (20, 41)
    assert (grid.spec.origin_x_m, grid.spec.origin_y_m) == (-1.0, 2.0)


def test_invalid_zero_readings_change_nothing() -> None:
    spec = GridSpec(0.0, 0.0, 0.05, 80, 80)
    grid = LogOddsGrid(spec, MappingConfig())
    grid.integrate(
        np.zeros(8), np.linspace(-np.pi, np.pi, 8, endpoint=False), np.array([2.0, 2.0, 0.0])
    )
    assert not grid.known_mask().any()


def test_adding_an_update_to_the_grids_equals_numpy_indexing() -> None:
    """The one-pass kernel against NumPy on random unique cells: both grids and the
    window get sign x increments, the block spans the cells, and a window that misses a
    cell is reported and left alone."""
    rng = np.random.default_rng(5)
    shape = (60, 80)
    flat = rng.choice(shape[0] * shape[1], size=500, replace=False)
    flat = flat[(flat // shape[1] >= 10) & (flat // shape[1] < 50)]  # rows 10..49
    increments = rng.integers(-1000, 1000, size=len(flat))
    rows, cols = np.divmod(flat, shape[1])
    for sign in (1, -1):
        global_acc = rng.integers(-50, 50, size=shape)
        robot_acc = rng.integers(-50, 50, size=shape)
        window = rng.integers(-50, 50, size=(45, 80))  # grid rows 8..52
        expected_global, expected_robot, expected_window = (
            global_acc.copy(),
            robot_acc.copy(),
            window.copy(),
        )
        expected_global.reshape(-1)[flat] += sign * increments
        expected_robot.reshape(-1)[flat] += sign * increments
        expected_window[rows - 8, cols] += sign * increments
        result = _add_to_grids(flat, increments, sign, global_acc, robot_acc, True, window, 8, 0)
        assert result == (rows.min(), rows.max() + 1, cols.min(), cols.max() + 1, True)
        assert np.array_equal(global_acc, expected_global)
        assert np.array_equal(robot_acc, expected_robot)
        assert np.array_equal(window, expected_window)
        narrow = window[:, :40].copy()
        before = narrow.copy()
        *_, inside = _add_to_grids(
            flat, increments, sign, global_acc, robot_acc, True, narrow, 8, 0
        )
        assert not inside and np.array_equal(narrow, before)
