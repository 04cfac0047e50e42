"""The coarse travel graph against exact Dijkstra on the costmap."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from scipy import ndimage

from acslam.config import CostmapConfig, FloorplanWorld
from acslam.mapping.costmap import compute_costmap
from acslam.planning.astar import path_costs_to
from acslam.planning.travel_graph import TravelGraph, TravelGraphBuilder, travel_costs
from acslam.worlds.floorplan import floorplan_world
from acslam.worlds.mapio import world_cells

RES_M = 0.05


def rooms_map(rng: np.random.Generator, size: int = 160) -> np.ndarray:
    """Lethal cells of a grid of rooms: walls 5 cells thick (a wall plus the inflation of
    a robot radius), a door 8-14 cells wide at a random place in each wall, and a few
    random pillars."""
    lethal = np.zeros((size, size), dtype=bool)
    lethal[:3], lethal[-3:], lethal[:, :3], lethal[:, -3:] = True, True, True, True
    for wall in range(40, size - 20, 40):
        lethal[wall - 2 : wall + 3] = True
        lethal[:, wall - 2 : wall + 3] = True
    for wall in range(40, size - 20, 40):
        for room in range(0, size, 40):
            width = int(rng.integers(8, 15))
            at = room + int(rng.integers(5, 40 - width - 4))
            lethal[wall - 2 : wall + 3, at : at + width] = False
            at = room + int(rng.integers(5, 40 - width - 4))
            lethal[at : at + width, wall - 2 : wall + 3] = False
    pillars = ndimage.binary_dilation(rng.random((size, size)) < 0.002, iterations=3)
    return lethal | pillars


def exact_costs(lethal: np.ndarray, starts: np.ndarray, targets: np.ndarray) -> np.ndarray:
    cost = np.zeros(lethal.shape)
    return np.array([path_costs_to(cost, lethal, tuple(s), targets, RES_M, 0.0) for s in starts])


def graph_costs(
    lethal: np.ndarray, starts: np.ndarray, targets: np.ndarray, block_cells: int
) -> np.ndarray:
    cost = np.zeros(lethal.shape)
    graph = TravelGraphBuilder().build(cost, lethal, RES_M, 0.0, block_cells)
    return travel_costs(graph, cost, lethal, starts, targets, RES_M, 0.0, end_blocks=1)


def free_cells(lethal: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
    free = np.argwhere(~lethal)
    return free[rng.choice(len(free), count, replace=False)]


@pytest.mark.parametrize("seed", range(3))
def test_one_cell_blocks_give_exact_dijkstra(seed: int) -> None:
    """With 1-cell blocks every free cell is a node and every edge an A* step."""
    rng = np.random.default_rng(seed)
    lethal = rooms_map(rng, 80)
    starts, targets = free_cells(lethal, rng, 3), free_cells(lethal, rng, 12)
    np.testing.assert_allclose(
        graph_costs(lethal, starts, targets, 1), exact_costs(lethal, starts, targets), rtol=1e-12
    )


@pytest.mark.parametrize(("seed", "block_cells"), [(0, 4), (1, 4), (2, 8), (3, 12)])
def test_reachability_is_exact_and_the_error_stays_under_two_blocks(
    seed: int, block_cells: int
) -> None:
    """A door every 2 m is the worst case: each door can cost up to a block's detour
    through its representative (measured over 10 seeds: at most 1.8 block sides)."""
    rng = np.random.default_rng(seed)
    lethal = rooms_map(rng)
    # A closed room: its cells are reachable from nowhere else, however coarse the blocks.
    lethal[100:103, 100:140] = lethal[137:140, 100:140] = True
    lethal[100:140, 100:103] = lethal[100:140, 137:140] = True
    starts = np.vstack([free_cells(lethal, rng, 4), [[120, 120]]])
    targets = np.vstack([free_cells(lethal, rng, 40), [[110, 130]]])
    exact = exact_costs(lethal, starts, targets)
    approx = graph_costs(lethal, starts, targets, block_cells)
    reachable = np.isfinite(exact)
    assert (~reachable).any() and reachable.any()
    np.testing.assert_array_equal(np.isfinite(approx), reachable)
    error_m = np.abs(approx[reachable] - exact[reachable])
    assert error_m.max() <= 2 * block_cells * RES_M


def test_on_a_real_floor_plan_lengths_are_within_five_percent(shared_dataset) -> None:
    """office_a, fully known, 0.2 m blocks (the allocator's default): every robot-target
    path length within 5 % of the exact one (measured: 2.3 % at most)."""
    office_a = shared_dataset("datasets/floorplans_ipa/office_a.png")
    world = floorplan_world(FloorplanWorld(generator="floorplan", file=office_a))
    costmap = compute_costmap(world_cells(world), world.spec, CostmapConfig(), 0.105)
    rng = np.random.default_rng(0)
    starts, targets = free_cells(costmap.lethal, rng, 3), free_cells(costmap.lethal, rng, 30)
    exact = exact_costs(costmap.lethal, starts, targets)
    approx = graph_costs(costmap.lethal, starts, targets, 4)
    reachable = np.isfinite(exact)
    np.testing.assert_array_equal(np.isfinite(approx), reachable)
    relative = np.abs(approx[reachable] - exact[reachable]) / exact[reachable]
    assert relative.max() <= 0.05


def test_a_one_cell_diagonal_wall_does_not_leak() -> None:
    """Two halves split by a diagonal line of lethal cells: blocks straddle the line, but
    their two sides are separate nodes and the corner rule keeps them apart."""
    size = 64
    lethal = np.zeros((size, size), dtype=bool)
    lethal[np.arange(size), np.arange(size)] = True
    starts = np.array([[40, 10], [10, 40]])
    targets = np.array([[60, 2], [2, 60], [33, 30]])
    exact = exact_costs(lethal, starts, targets)
    for block_cells in (3, 8, 16):
        approx = graph_costs(lethal, starts, targets, block_cells)
        np.testing.assert_array_equal(np.isfinite(approx), np.isfinite(exact))


def test_targets_next_to_the_robot_and_lethal_targets() -> None:
    lethal = np.zeros((48, 48), dtype=bool)
    lethal[20:28, 20:28] = True
    starts = np.array([[10, 10]])
    targets = np.array([[10, 10], [12, 13], [24, 24]])
    approx = graph_costs(lethal, starts, targets, 8)
    exact = exact_costs(lethal, starts, targets)
    np.testing.assert_allclose(approx[:, :2], exact[:, :2], rtol=1e-12)  # fine in the box
    assert approx[0, 2] == np.inf == exact[0, 2]


def test_the_searches_give_the_same_costs_on_any_number_of_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The robots' searches run in lanes on threads, each with its own workspace: one
    thread or several, the costs are the same to the bit."""
    rng = np.random.default_rng(4)
    lethal = rooms_map(rng)
    starts, targets = free_cells(lethal, rng, 7), free_cells(lethal, rng, 30)
    costs = {}
    for threads in (1, 3, 8):
        monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", threads)
        costs[threads] = graph_costs(lethal, starts, targets, 4)
    np.testing.assert_array_equal(costs[3], costs[1])
    np.testing.assert_array_equal(costs[8], costs[1])
    assert np.isfinite(costs[1]).sum() > len(starts)
    np.testing.assert_allclose(costs[1], exact_costs(lethal, starts, targets), atol=8 * RES_M)


GRAPH_ARRAYS = ("node_cells", "block_nodes", "offsets", "neighbours", "costs")


def assert_same_graph(incremental: TravelGraph, fresh: TravelGraph) -> None:
    for field in GRAPH_ARRAYS:
        np.testing.assert_array_equal(getattr(incremental, field), getattr(fresh, field))


@pytest.mark.parametrize(("seed", "block_cells"), [(0, 4), (1, 7), (2, 10)])
def test_a_builder_that_relabels_changed_blocks_gives_the_fresh_graph(
    seed: int, block_cells: int
) -> None:
    """After any sequence of map updates (obstacles appearing, doors opening, speckle
    that splits blocks into many components, costs changing everywhere), the graph a
    builder patches from its last one equals, array for array, a fresh build."""
    rng = np.random.default_rng(seed)
    size = 150
    lethal = rooms_map(rng, size)
    builder = TravelGraphBuilder()
    for _ in range(40):
        r, c = rng.integers(0, size - 1, 2)
        height, width = rng.integers(1, 16, 2)
        patch = lethal[r : r + height, c : c + width]
        patch[:] = rng.random(patch.shape) < rng.choice([0.0, 0.3, 1.0])
        cost = rng.random(lethal.shape)
        assert_same_graph(
            builder.build(cost, lethal, RES_M, 2.0, block_cells),
            TravelGraphBuilder().build(cost, lethal, RES_M, 2.0, block_cells),
        )


def test_a_builder_starts_over_when_the_window_or_the_block_size_changes() -> None:
    rng = np.random.default_rng(3)
    builder = TravelGraphBuilder()
    for size, block_cells in ((120, 4), (160, 4), (160, 6), (100, 6)):
        lethal = rooms_map(rng, size)
        cost = np.zeros(lethal.shape)
        assert_same_graph(
            builder.build(cost, lethal, RES_M, 0.0, block_cells),
            TravelGraphBuilder().build(cost, lethal, RES_M, 0.0, block_cells),
        )
