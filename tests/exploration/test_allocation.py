"""Frontier allocation: exact MAP vs brute force, conflicts, walls, approximation gap."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from acslam.config import CostmapConfig
from acslam.exploration.allocation import (
    joint_assignment_count,
    log_objective,
    solve_approximate,
    solve_exact,
    unary_log_factors,
)
from acslam.exploration.clustering import FrontierCluster
from acslam.exploration.params import FactorGraphParams
from acslam.grid import GridSpec
from acslam.mapping.costmap import compute_costmap
from acslam.pipeline.registry import ALLOCATORS


def allocate(robot_cells, clusters, costmap, name="factor-graph", **params):
    """The registered allocator ``name`` with ``params`` over its defaults."""
    allocator = ALLOCATORS.create(ALLOCATORS.get(name).params(**params))
    return allocator.allocate(robot_cells, clusters, costmap)


LAMBDAS = (0.01, 0.5, 1.0, 2.0, -3.0, -40.0)


def _brute_force_value(
    distances: np.ndarray, sizes: np.ndarray, alpha: float, beta: float, lam: float
) -> float:
    """max over every assignment of reachable clusters of the log of eq. 4.37, written out."""
    robots, clusters = distances.shape
    options = [[k for k in range(clusters) if np.isfinite(distances[i, k])] for i in range(robots)]
    best = -math.inf
    for x in itertools.product(*options):
        value = 0.0
        for i in range(robots):
            value += -alpha * distances[i, x[i]] + beta * sizes[x[i]]
        for i in range(robots):
            for j in range(i + 1, robots):
                value += lam if x[i] == x[j] else 1.0
        best = max(best, value)
    return best


def _random_instance(rng: np.random.Generator, robots: int, clusters: int) -> np.ndarray:
    distances = rng.uniform(0.0, 12.0, (robots, clusters))
    distances[rng.random((robots, clusters)) < 0.2] = np.inf
    distances[np.arange(robots), rng.integers(0, clusters, robots)] = rng.uniform(0, 12, robots)
    return distances


def test_exact_factor_graph_equals_brute_force() -> None:
    rng = np.random.default_rng(11)
    for _ in range(120):
        robots, clusters = int(rng.integers(1, 5)), int(rng.integers(1, 7))
        distances = _random_instance(rng, robots, clusters)
        sizes = rng.integers(3, 80, clusters).astype(float)
        alpha, beta = float(rng.uniform(0.2, 2.0)), float(rng.uniform(0.0, 0.1))
        lam = float(rng.choice(LAMBDAS))
        unary = unary_log_factors(distances, sizes, alpha, beta)
        x = solve_exact(unary, lam)
        assert all(np.isfinite(distances[i, k]) for i, k in enumerate(x))
        expected = _brute_force_value(distances, sizes, alpha, beta, lam)
        assert log_objective(x, unary, lam) == pytest.approx(expected, abs=1e-9)


def test_strong_conflict_penalty_gives_distinct_clusters() -> None:
    rng = np.random.default_rng(12)
    for _ in range(60):
        robots = int(rng.integers(2, 6))
        clusters = int(rng.integers(robots, 9))
        # Everyone prefers the same cluster 0 by far.
        distances = rng.uniform(5.0, 10.0, (robots, clusters))
        distances[:, 0] = 0.5
        unary = unary_log_factors(distances, np.full(clusters, 10.0), 1.0, 0.05)
        x = solve_exact(unary, -40.0)
        assert len(set(x)) == robots
        # With the thesis's weak lambda they would share the near cluster.
        assert len(set(solve_exact(unary, 0.01))) < robots


def _corridor_world() -> tuple[GridSpec, np.ndarray]:
    """10 m x 4 m room, a wall at x = 5 m with a gap only at the far top end.

    Robot at (4, 1): cluster A just behind the wall at (6, 1) is 2 m away in a straight
    line but needs the detour through the gap (~6 m); cluster B at (1, 1) is 3 m away.
    """
    spec = GridSpec(0.0, 0.0, 0.1, 40, 100)
    values = np.zeros(spec.shape, dtype=np.int8)
    values[[0, -1], :] = 100
    values[:, [0, -1]] = 100
    values[:35, 50] = 100  # wall at x = 5.0-5.1 m, open above y = 3.5 m
    return spec, values


def _cluster_at(spec: GridSpec, xy: tuple[float, float], size: int = 10) -> FrontierCluster:
    cell = spec.world_to_cell(np.array(xy))[0]
    return FrontierCluster(
        cells=np.repeat(cell[None, :], size, axis=0),
        centroid_m=np.array(xy),
        target_cell=cell,
        target_m=spec.cell_to_world(cell)[0],
        size_cells=size,
        information_gain_cells=0,
    )


def test_path_distance_respects_walls() -> None:
    spec, values = _corridor_world()
    costmap = compute_costmap(values, spec, CostmapConfig(), 0.1)
    clusters = [_cluster_at(spec, (6.0, 1.0)), _cluster_at(spec, (1.0, 1.0))]
    robot = spec.world_to_cell(np.array([4.0, 1.0]))
    by_path = allocate(robot, clusters, costmap)
    assert by_path.cluster_of_robot == (1,)
    assert by_path.distances_m[0, 0] > 5.0 > 3.5 > by_path.distances_m[0, 1]
    by_line = allocate(robot, clusters, costmap, "thesis")
    assert by_line.cluster_of_robot == (0,)
    for method in ("hungarian", "greedy"):
        result = allocate(robot, clusters, costmap, method)
        assert result.cluster_of_robot == (1,)


@pytest.mark.parametrize("gap", [True, False])
def test_travel_graph_distances_follow_the_exact_paths(gap: bool) -> None:
    """The coarse metric decides as the exact one, is as strict about reachability and
    stays within two 0.2 m blocks of the exact lengths."""
    spec, values = _corridor_world()
    if not gap:
        values[:, 50] = 100
    costmap = compute_costmap(values, spec, CostmapConfig(), 0.1)
    clusters = [_cluster_at(spec, xy) for xy in ((6.0, 1.0), (1.0, 1.0), (8.0, 3.0))]
    robots = spec.world_to_cell(np.array([[4.0, 1.0], [9.0, 1.0]]))
    exact = allocate(robots, clusters, costmap)
    coarse = allocate(robots, clusters, costmap, distance_metric="travel-graph")
    assert coarse.cluster_of_robot == exact.cluster_of_robot
    reachable = np.isfinite(exact.distances_m)
    np.testing.assert_array_equal(np.isfinite(coarse.distances_m), reachable)
    assert (~reachable).any() != gap
    error_m = np.abs(coarse.distances_m[reachable] - exact.distances_m[reachable])
    assert error_m.max() <= 0.4


def test_robot_without_reachable_cluster_is_idle_and_unreachable_clusters_are_excluded() -> None:
    spec, values = _corridor_world()
    values[:, 50] = 100  # close the gap: the right half is cut off
    costmap = compute_costmap(values, spec, CostmapConfig(), 0.1)
    clusters = [_cluster_at(spec, (6.0, 1.0)), _cluster_at(spec, (8.0, 3.0))]
    robots = spec.world_to_cell(np.array([[4.0, 1.0], [9.0, 1.0], [7.0, 2.0]]))
    for method in ("factor-graph", "hungarian", "greedy"):
        result = allocate(robots, clusters, costmap, method)
        assert result.status(0) == "idle"
        assert result.cluster_of_robot[1:] in {(0, 1), (1, 0)}
        assert np.isinf(result.distances_m[0]).all()


def test_large_instances_switch_to_the_approximate_solver() -> None:
    rng = np.random.default_rng(13)
    spec = GridSpec(0.0, 0.0, 0.1, 60, 60)
    values = np.zeros(spec.shape, dtype=np.int8)
    costmap = compute_costmap(values, spec, CostmapConfig(), 0.1)
    clusters = [_cluster_at(spec, tuple(rng.uniform(0.5, 5.5, 2))) for _ in range(20)]
    robots = rng.integers(5, 55, (8, 2))
    config = FactorGraphParams()
    result = allocate(robots, clusters, costmap)
    assert joint_assignment_count(np.zeros((8, 20)), config.conflict_lambda) == 8**8
    assert result.solver == "approximate"
    assert all(k is not None for k in result.cluster_of_robot)
    small = allocate(robots[:3], clusters, costmap)
    assert small.solver == "exact"


def test_approximate_solver_gap_on_instances_exact_can_solve() -> None:
    """Measured on these 300 random instances (2-6 robots, 2-20 clusters, lambda <= 1):
    optimal in 292, mean gap 0.07 % of |J*| (J* floored at 1), max 7.2 %."""
    rng = np.random.default_rng(14)
    gaps, optimal = [], 0
    for _ in range(300):
        robots, clusters = int(rng.integers(2, 7)), int(rng.integers(2, 21))
        lam = float(rng.choice(LAMBDAS[:3] + LAMBDAS[4:]))  # lambda <= 1: exact stays small
        distances = _random_instance(rng, robots, clusters)
        unary = unary_log_factors(distances, rng.integers(5, 120, clusters), 1.0, 0.05)
        assert joint_assignment_count(unary, lam) <= FactorGraphParams().exact_max_joint_assignments
        exact = log_objective(solve_exact(unary, lam), unary, lam)
        approx = log_objective(solve_approximate(unary, lam), unary, lam)
        assert approx <= exact + 1e-9
        gaps.append((exact - approx) / max(abs(exact), 1.0))
        optimal += exact - approx < 1e-9
    print(f"approximate: optimal {optimal}/300, mean gap {np.mean(gaps):.2%}, max {max(gaps):.2%}")
    assert optimal >= 0.95 * 300
    assert np.mean(gaps) <= 0.01
