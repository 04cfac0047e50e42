"""Costmap (eqs. 4.35-4.36) against a brute-force loop over every obstacle cell, and its
updates near changes against computing it afresh."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.config import CostmapConfig
from acslam.grid import GridSpec, Window
from acslam.mapping.costmap import LETHAL_COST, CostmapUpdater, compute_costmap

SPEC = GridSpec(1.0, -2.0, 0.1, 30, 40)
CONFIG = CostmapConfig(cost_max=2.0, decay_lambda_per_m=3.0, radius_m=0.65, unknown_cost=0.3)
ROBOT_RADIUS_M = 0.25  # radii off the sqrt(integer) cell lattice: no ties


def _random_values(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    values = np.zeros(SPEC.shape, dtype=np.int8)
    values[rng.random(SPEC.shape) < 0.03] = 100
    values[rng.random(SPEC.shape) < 0.2] = -1
    return values


def _brute_force(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4.36 literally: max over obstacles within r of C_max exp(-lambda d)."""
    cells = np.argwhere(np.ones(SPEC.shape, dtype=bool))
    centres = SPEC.cell_to_world(cells)
    obstacles = SPEC.cell_to_world(np.argwhere(values == 100))
    cost = np.zeros(len(cells))
    nearest = np.full(len(cells), np.inf)
    for ox, oy in obstacles:
        d = np.hypot(centres[:, 0] - ox, centres[:, 1] - oy)
        contribution = np.where(d <= CONFIG.radius_m, CONFIG.cost_max * np.exp(-3.0 * d), 0.0)
        cost = np.maximum(cost, contribution)
        nearest = np.minimum(nearest, d)
    return cost.reshape(SPEC.shape), nearest.reshape(SPEC.shape)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_costmap_matches_max_over_obstacles(seed: int) -> None:
    values = _random_values(seed)
    costmap = compute_costmap(values, SPEC, CONFIG, ROBOT_RADIUS_M)
    expected_cost, expected_distance = _brute_force(values)
    np.testing.assert_allclose(costmap.distance_m, expected_distance, atol=1e-12)

    lethal = expected_distance <= ROBOT_RADIUS_M
    assert np.array_equal(costmap.lethal, lethal)
    assert (costmap.cost[lethal] == LETHAL_COST).all()

    unknown = (values == -1) & ~lethal
    np.testing.assert_allclose(
        costmap.cost[unknown], np.maximum(expected_cost[unknown], CONFIG.unknown_cost)
    )
    known = (values != -1) & ~lethal
    np.testing.assert_allclose(costmap.cost[known], expected_cost[known], atol=1e-12)
    assert (costmap.cost[known & (expected_distance > CONFIG.radius_m)] == 0.0).all()


def test_distances_are_exact_roots_of_integer_squared_distances() -> None:
    """Bit for bit: whatever block or thread computes a cell, it gets the same value."""
    values = _random_values(4)
    costmap = compute_costmap(values, SPEC, CONFIG, ROBOT_RADIUS_M)
    cells = np.argwhere(np.ones(SPEC.shape, dtype=bool))
    obstacles = np.argwhere(values == 100)
    squared = ((cells[:, None, :] - obstacles[None, :, :]) ** 2).sum(axis=2).min(axis=1)
    expected = np.sqrt(squared.astype(float)) * SPEC.resolution_m
    np.testing.assert_array_equal(costmap.distance_m, expected.reshape(SPEC.shape))


def test_empty_map_has_no_obstacle_costs() -> None:
    values = np.full(SPEC.shape, -1, dtype=np.int8)
    values[:, :10] = 0
    costmap = compute_costmap(values, SPEC, CONFIG, ROBOT_RADIUS_M)
    assert np.isinf(costmap.distance_m).all() and not costmap.lethal.any()
    assert (costmap.cost[:, :10] == 0.0).all() and (costmap.cost[:, 10:] == 0.3).all()


def test_shape_mismatch_is_rejected() -> None:
    with pytest.raises(ValueError, match="shape"):
        compute_costmap(np.zeros((3, 3), dtype=np.int8), SPEC, CONFIG, ROBOT_RADIUS_M)


def test_a_reach_caps_the_distances_and_nothing_else() -> None:
    values = _random_values(3)
    exact = compute_costmap(values, SPEC, CONFIG, ROBOT_RADIUS_M)
    capped = compute_costmap(values, SPEC, CONFIG, ROBOT_RADIUS_M, reach_m=0.8)
    np.testing.assert_array_equal(capped.distance_m, np.minimum(exact.distance_m, 0.8))
    np.testing.assert_array_equal(capped.cost, exact.cost)
    np.testing.assert_array_equal(capped.lethal, exact.lethal)


def _sub_window(spec: GridSpec, row0: int, col0: int, rows: int, cols: int) -> Window:
    origin_x_m = spec.origin_x_m + col0 * spec.resolution_m
    origin_y_m = spec.origin_y_m + row0 * spec.resolution_m
    return Window(row0, col0, GridSpec(origin_x_m, origin_y_m, spec.resolution_m, rows, cols))


@pytest.mark.parametrize("seed", [0, 1])
def test_updates_near_changes_equal_computing_afresh(seed: int) -> None:
    """A growing window over a 600 x 600 map that changes in patches: obstacles appear
    and vanish, cells become known; every update equals :func:`compute_costmap` on the
    window with the same reach, to the bit. A shrinking window starts afresh."""
    rng = np.random.default_rng(seed)
    spec = GridSpec(0.0, 0.0, 0.05, 600, 600)
    values = np.full(spec.shape, -1, dtype=np.int8)
    values[200:400, 200:400] = 0
    values[rng.random(spec.shape) < 0.001] = 100  # sparse: distances up to the reach
    updater = CostmapUpdater(CONFIG, ROBOT_RADIUS_M, reach_m=1.0)
    bounds = np.array([180, 180, 240, 260])  # row0, col0, rows, cols
    for step in range(25):
        for _ in range(int(rng.integers(1, 4))):
            r, c = rng.integers(150, 450, size=2)
            patch = values[r : r + rng.integers(2, 20), c : c + rng.integers(2, 20)]
            patch[...] = rng.choice(
                np.array([-1, 0, 100], dtype=np.int8), p=[0.3, 0.69, 0.01], size=patch.shape
            )
        if step == 20:
            bounds = np.array([250, 250, 100, 100])
        else:
            grow = rng.integers(0, 12, size=4)
            bounds = np.array([bounds[0] - grow[0], bounds[1] - grow[1], 0, 0]) + np.array(
                [0, 0, bounds[2] + grow[0] + grow[2], bounds[3] + grow[1] + grow[3]]
            )
            bounds = np.clip(bounds, 0, 600)
            bounds[2:] = np.minimum(bounds[2:], 600 - bounds[:2])
        window = _sub_window(spec, *(int(b) for b in bounds))
        crop = window.crop(values)
        costmap = updater.update(crop, window)
        expected = compute_costmap(crop, window.spec, CONFIG, ROBOT_RADIUS_M, reach_m=1.0)
        np.testing.assert_array_equal(costmap.distance_m, expected.distance_m)
        np.testing.assert_array_equal(costmap.cost, expected.cost)
        np.testing.assert_array_equal(costmap.lethal, expected.lethal)


def test_values_changing_beside_unchanged_walls_refill_costs_exactly() -> None:
    """Cells turning known or unknown within a wall's cost radius, no wall moving: the
    costs follow (unknown cells cost at least ``unknown_cost``), equal to computing
    afresh to the bit, also after an update that changed nothing."""
    rng = np.random.default_rng(3)
    spec = GridSpec(0.0, 0.0, 0.05, 200, 260)
    values = np.full(spec.shape, -1, dtype=np.int8)
    values[40:160, 40:220] = 0
    values[100, 60:200] = 100  # a wall
    window = Window(0, 0, spec)
    updater = CostmapUpdater(CONFIG, ROBOT_RADIUS_M, reach_m=1.0)
    updater.update(values, window)
    for _ in range(6):
        r, c = int(rng.integers(85, 110)), int(rng.integers(50, 200))
        patch = values[r : r + 8, c : c + 30]
        patch[patch != 100] = rng.choice(np.array([-1, 0], dtype=np.int8), size=patch.shape)[
            patch != 100
        ]
        for _ in range(2):
            costmap = updater.update(values, window)
            expected = compute_costmap(values, spec, CONFIG, ROBOT_RADIUS_M, reach_m=1.0)
            np.testing.assert_array_equal(costmap.cost, expected.cost)
            np.testing.assert_array_equal(costmap.distance_m, expected.distance_m)
            np.testing.assert_array_equal(costmap.lethal, expected.lethal)
