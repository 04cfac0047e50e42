"""A*, Dijkstra, snapping, shortcutting and lookahead against brute force and geometry."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import ndimage, sparse
from scipy.sparse.csgraph import dijkstra

from acslam.errors import AcslamError, NoPathError
from acslam.geometry import path_length_m
from acslam.grid import GridSpec
from acslam.planning.astar import (
    astar_cells,
    lookahead_point,
    path_costs_to,
    plan_path,
    remaining_length_m,
    shortcut_cells,
)

RES_M = 0.1
WEIGHT = 3.0


def random_map(rng: np.random.Generator, size: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Random lethal blobs and a smooth random cost in [0, 1]."""
    seeds = rng.random((size, size)) < 0.04
    lethal = ndimage.binary_dilation(seeds, iterations=int(rng.integers(1, 3)))
    cost = ndimage.gaussian_filter(rng.random((size, size)), 2.0)
    cost = (cost - cost.min()) / (np.ptp(cost) + 1e-12)
    return cost, lethal


def brute_force_graph(cost: np.ndarray, lethal: np.ndarray) -> sparse.csr_matrix:
    """The same 8-connected graph as the planner, edge by edge."""
    rows, cols = lethal.shape
    src, dst, weight = [], [], []
    for r in range(rows):
        for c in range(cols):
            if lethal[r, c]:
                continue
            for dr in (-1, 0, 1):
                for dc in (-1, 0, 1):
                    nr, nc = r + dr, c + dc
                    if (dr, dc) == (0, 0) or not (0 <= nr < rows and 0 <= nc < cols):
                        continue
                    if lethal[nr, nc] or (dr and dc and lethal[nr, c] and lethal[r, nc]):
                        continue
                    src.append(r * cols + c)
                    dst.append(nr * cols + nc)
                    weight.append(RES_M * math.hypot(dr, dc) * (1 + WEIGHT * cost[nr, nc]))
    return sparse.csr_matrix((weight, (src, dst)), shape=(rows * cols, rows * cols))


def step_cost(cells: np.ndarray, cost: np.ndarray) -> float:
    steps = np.diff(cells, axis=0)
    lengths = RES_M * np.hypot(steps[:, 0], steps[:, 1])
    return float((lengths * (1 + WEIGHT * cost[cells[1:, 0], cells[1:, 1]])).sum())


def test_astar_cost_matches_brute_force_dijkstra_on_random_maps() -> None:
    rng = np.random.default_rng(7)
    compared = 0
    for _ in range(50):
        cost, lethal = random_map(rng)
        free = np.argwhere(~lethal)
        start, goal = free[rng.choice(len(free), 2, replace=False)]
        cols = lethal.shape[1]
        best = dijkstra(brute_force_graph(cost, lethal), indices=start[0] * cols + start[1])
        expected = best[goal[0] * cols + goal[1]]
        if not np.isfinite(expected):
            with pytest.raises(NoPathError):
                astar_cells(cost, lethal, tuple(start), tuple(goal), RES_M, WEIGHT)
            continue
        cells, path_cost = astar_cells(cost, lethal, tuple(start), tuple(goal), RES_M, WEIGHT)
        assert path_cost == pytest.approx(expected, rel=1e-9)
        assert step_cost(cells, cost) == pytest.approx(expected, rel=1e-9)
        assert not lethal[cells[:, 0], cells[:, 1]].any()
        assert np.abs(np.diff(cells, axis=0)).max() == 1
        assert (cells[0] == start).all() and (cells[-1] == goal).all()
        every_cell = np.argwhere(np.ones_like(lethal))
        dist = path_costs_to(cost, lethal, tuple(start), every_cell, RES_M, WEIGHT)
        np.testing.assert_allclose(dist, best, rtol=1e-9)
        # A few targets stop the search early and get the same, final, costs.
        few = free[rng.choice(len(free), 3, replace=False)]
        early = path_costs_to(cost, lethal, tuple(start), few, RES_M, WEIGHT)
        np.testing.assert_array_equal(early, dist[few[:, 0] * cols + few[:, 1]])
        compared += 1
    assert compared >= 40


def test_no_corner_cutting_between_two_lethal_cells() -> None:
    lethal = np.zeros((3, 3), dtype=bool)
    lethal[0, 1] = lethal[1, 0] = True
    lethal[1, 2] = lethal[2, 1] = True
    with pytest.raises(NoPathError):
        astar_cells(np.zeros((3, 3)), lethal, (0, 0), (1, 1), RES_M, WEIGHT)


def test_walled_off_goal_raises_a_named_error() -> None:
    lethal = np.zeros((20, 20), dtype=bool)
    lethal[8:13, 8] = lethal[8:13, 12] = lethal[8, 8:13] = lethal[12, 8:13] = True
    grid = GridSpec(0.0, 0.0, RES_M, 20, 20)
    with pytest.raises(NoPathError, match=r"from \(0.15, 0.15\) m to \(1.05, 1.05\) m") as info:
        plan_path(
            np.zeros((20, 20)),
            lethal,
            grid,
            np.array([0.15, 0.15]),
            np.array([1.05, 1.05]),
            cost_weight=WEIGHT,
            max_snap_m=0.0,
            shortcut=False,
        )
    assert isinstance(info.value, AcslamError)


def test_start_and_goal_snap_to_the_nearest_free_cell_within_the_radius() -> None:
    lethal = np.zeros((20, 20), dtype=bool)
    lethal[5:10, 5:10] = True
    grid = GridSpec(0.0, 0.0, RES_M, 20, 20)
    start = grid.cell_to_world([[6, 5]])[0]  # one cell inside the blob's left edge
    snap = {"cost_weight": WEIGHT, "max_snap_m": 0.15, "shortcut": False}
    path = plan_path(np.zeros((20, 20)), lethal, grid, start, np.array([1.85, 1.85]), **snap)
    assert tuple(path.cells[0]) == (6, 4)
    deep = grid.cell_to_world([[7, 7]])[0]  # 3 cells from free space
    with pytest.raises(NoPathError, match="no free cell within 1 cells"):
        plan_path(np.zeros((20, 20)), lethal, grid, deep, np.array([1.85, 1.85]), **snap)


def crosses_lethal(points: np.ndarray, lethal: np.ndarray) -> bool:
    """Densely sample the polyline (cell units) and look for a sample inside a lethal cell."""
    for a, b in itertools.pairwise(points):
        t = np.linspace(0.0, 1.0, 200 * int(np.abs(b - a).max() + 1))[:, None]
        samples = a + t * (b - a)
        frac = samples - np.floor(samples)
        interior = ((frac > 1e-6) & (frac < 1 - 1e-6)).all(axis=1)
        cells = np.floor(samples[interior]).astype(int)
        if lethal[cells[:, 0], cells[:, 1]].any():
            return True
    return False


def test_shortcut_never_crosses_lethal_cells_and_is_not_longer() -> None:
    rng = np.random.default_rng(3)
    shortened = 0
    for _ in range(30):
        cost, lethal = random_map(rng)
        free = np.argwhere(~lethal)
        start, goal = free[rng.choice(len(free), 2, replace=False)]
        try:
            cells, _ = astar_cells(cost, lethal, tuple(start), tuple(goal), RES_M, WEIGHT)
        except NoPathError:
            continue
        smooth = shortcut_cells(cells, lethal)
        assert (smooth[0] == cells[0]).all() and (smooth[-1] == cells[-1]).all()
        assert not crosses_lethal(smooth + 0.5, lethal)
        raw_m, smooth_m = path_length_m(cells * RES_M), path_length_m(smooth * RES_M)
        assert smooth_m <= raw_m + 1e-12
        shortened += smooth_m < raw_m - 1e-9
    assert shortened > 10


def test_lookahead_on_an_l_shaped_path() -> None:
    path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    robot = np.array([0.5, 0.3])  # projects onto (0.5, 0) of the first leg
    np.testing.assert_allclose(lookahead_point(path, robot, 1.0), [1.5, 0.0])
    np.testing.assert_allclose(lookahead_point(path, robot, 2.0), [2.0, 0.5])
    np.testing.assert_allclose(lookahead_point(path, robot, 9.0), [2.0, 2.0])
    np.testing.assert_allclose(lookahead_point(path, np.array([2.4, 1.0]), 0.5), [2.0, 1.5])


def test_remaining_length_goes_along_the_path_from_the_projection() -> None:
    path = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    assert remaining_length_m(path, np.array([0.5, 0.3])) == pytest.approx(0.3 + 1.5 + 2.0)
    assert remaining_length_m(path, np.array([2.0, 2.0])) == pytest.approx(0.0)
    assert remaining_length_m(path[:1], np.array([3.0, 4.0])) == pytest.approx(5.0)
