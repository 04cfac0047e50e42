"""Costmap (eqs. 4.35-4.36) against a brute-force loop over every obstacle cell."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.config import CostmapConfig
from acslam.grid import GridSpec
from acslam.mapping.costmap import LETHAL_COST, compute_costmap

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
