"""The grid's nearest neighbours within a bound against brute force and scipy's cKDTree."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from acslam.mapping.nearest_points import point_grid


def brute_force(points: np.ndarray, queries: np.ndarray, bound_m: float):
    """Every distance measured: the nearest point strictly within the bound."""
    differences = points[None, :, :] - queries[:, None, :]
    squared = differences[..., 0] * differences[..., 0] + differences[..., 1] * differences[..., 1]
    nearest = np.argmin(squared, axis=1)
    best = squared[np.arange(len(queries)), nearest]
    within = best < bound_m * bound_m
    return np.where(within, np.sqrt(best), np.inf), np.where(within, nearest, -1)


def scan_like_points(rng: np.random.Generator) -> np.ndarray:
    """Walls of a 6 m x 4 m room sampled unevenly, with clutter: points bunched along
    lines, as a LiDAR gives them, and empty space between."""
    t = rng.uniform(0.0, 1.0, 400)
    side = rng.integers(0, 4, 400)
    corners = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0], [0.0, 0.0]])
    walls = corners[side] + t[:, None] * (corners[side + 1] - corners[side])
    walls += rng.normal(0.0, 0.01, walls.shape)
    clutter = rng.uniform([1.0, 1.0], [5.0, 3.0], (60, 2))
    return np.vstack([walls, clutter])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("bound_m", [0.05, 0.1, 0.3, 1.0, 5.0])
def test_the_grid_finds_the_nearest_point_within_the_bound(seed: int, bound_m: float) -> None:
    rng = np.random.default_rng(seed)
    points = scan_like_points(rng)
    # Queries near the walls, in the open, and outside the points' bounding box.
    queries = np.vstack(
        [
            points[rng.integers(0, len(points), 300)] + rng.normal(0.0, 0.08, (300, 2)),
            rng.uniform(-3.0, 9.0, (300, 2)),
        ]
    )
    distances, matches = point_grid(points).nearest_within(queries, bound_m)
    expected_distances, expected_matches = brute_force(points, queries, bound_m)
    np.testing.assert_array_equal(matches, expected_matches)
    np.testing.assert_array_equal(distances, expected_distances)
    # Both outcomes occur: the bound is tested, not only the search.
    assert 0 < np.count_nonzero(matches >= 0) < len(queries) or bound_m == 5.0
    tree_distances, tree_matches = cKDTree(points).query(queries, distance_upper_bound=bound_m)
    np.testing.assert_array_equal(np.where(np.isfinite(tree_distances), tree_matches, -1), matches)
    np.testing.assert_array_equal(tree_distances, distances)


def test_a_long_range_scan_gets_large_cells_not_a_huge_grid() -> None:
    """180 points 80 m apart at most: no more cells than points, answers unchanged."""
    rng = np.random.default_rng(3)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 180)
    ranges = rng.uniform(1.0, 80.0, 180)
    points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)])
    grid = point_grid(points)
    assert grid.rows * grid.cols <= 2 * len(points)
    queries = points + rng.normal(0.0, 0.5, points.shape)
    distances, matches = grid.nearest_within(queries, 1.0)
    expected_distances, expected_matches = brute_force(points, queries, 1.0)
    np.testing.assert_array_equal(matches, expected_matches)
    np.testing.assert_array_equal(distances, expected_distances)


def test_no_points_or_one_point() -> None:
    queries = np.array([[0.0, 0.0], [0.3, 0.0], [2.0, 2.0]])
    distances, matches = point_grid(np.zeros((0, 2))).nearest_within(queries, 1.0)
    assert np.all(np.isinf(distances)) and np.all(matches == -1)
    distances, matches = point_grid(np.array([[0.0, 0.0]])).nearest_within(queries, 1.0)
    np.testing.assert_array_equal(matches, [0, 0, -1])
    np.testing.assert_array_equal(distances, [0.0, 0.3, np.inf])
