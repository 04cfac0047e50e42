"""Exploration speed: incremental EWFD vs the naive full-grid scan; DBSCAN and allocation.

Run: ``python benchmarks/exploration_speed.py`` (about a minute on 2 cores).

1. Frontiers. Three robots follow scripted A* paths (ground truth, 0.25 m clearance) in
   thesis world 4 (40 m x 40 m at 0.05 m: 800 x 800 cells), each scanning with the
   simulated LiDAR (360 beams, 8 m) every 0.25 m into a :class:`TeamMap`. After every
   round of scans both detectors run on the same map: EWFD (``update`` with the scan
   cells) and the naive one (vectorised frontier mask plus the free components of the
   robots, :func:`reachable_frontier_cells`); the sets are asserted equal at every step.
   The map read-out (``to_occupancy_values``) is shared input and not timed.
2. Clustering and allocation for 3, 5, 8 robots x 20 clusters on the final map of run 1,
   also reported relative to a reference measured in the same process (a 800 x 800
   float64 ``np.sort`` of the rows), so figures from different machines compare.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from functools import partial

import numpy as np

from acslam.config import (
    AllocationConfig,
    CostmapConfig,
    ExplorationConfig,
    LidarConfig,
    MappingConfig,
    RobotsConfig,
    ThesisWorld,
)
from acslam.exploration.allocation import (
    allocate,
    solve_approximate,
    solve_exact,
    unary_log_factors,
)
from acslam.exploration.clustering import FrontierCluster, cluster_frontiers
from acslam.exploration.frontiers import (
    EwfdFrontierDetector,
    active_radius_m,
    reachable_frontier_cells,
)
from acslam.mapping.costmap import compute_costmap
from acslam.mapping.occupancy import TeamMap
from acslam.planning.astar import astar_cells
from acslam.sim.lidar import LidarSensor
from acslam.worlds.generators import build_world
from acslam.worlds.world import World

STEP_M = 0.25
ROUNDS = 240


def scripted_paths(world: World, rng: np.random.Generator, robots: int) -> list[np.ndarray]:
    """Per robot, (ROUNDS, 2) positions every STEP_M along A* legs to random goals."""
    lethal = world.clearance_m < 0.25
    cost = np.zeros(world.spec.shape)
    free_cells = np.argwhere(~lethal & world.reachable_free(*world.default_starts[0, :2]))
    paths = []
    for k in range(robots):
        start = world.spec.world_to_cell(world.default_starts[k % len(world.default_starts), :2])
        current = tuple(int(v) for v in start[0])
        if lethal[current]:
            current = tuple(free_cells[np.argmin(((free_cells - current) ** 2).sum(axis=1))])
        points: list[np.ndarray] = []
        while len(points) < ROUNDS:
            goal = tuple(int(v) for v in free_cells[rng.integers(len(free_cells))])
            cells, _ = astar_cells(cost, lethal, current, goal, world.spec.resolution_m, 0.0)
            stride = max(1, round(STEP_M / world.spec.resolution_m))
            points.extend(world.spec.cell_to_world(cells[::stride]))
            current = goal
        paths.append(np.array(points[:ROUNDS]))
    return paths


def bench_frontiers() -> tuple[World, np.ndarray, np.ndarray, np.ndarray]:
    world = build_world(ThesisWorld(generator="thesis", experiment=4), 0)
    rng = np.random.default_rng(0)
    mapping = MappingConfig()
    team = TeamMap(world.spec, mapping)
    sensors = [LidarSensor(LidarConfig(), world, np.random.default_rng(k)) for k in range(3)]
    paths = scripted_paths(world, rng, 3)
    detector = EwfdFrontierDetector(world.spec, active_radius_m(mapping))
    no_discs = np.zeros((0, 3))
    ewfd_s, naive_s, frontier_counts = [], [], []
    values = np.zeros(0)
    robot_cells = np.zeros((0, 2))
    for step in range(ROUNDS):
        positions = np.array([path[step] for path in paths])
        for k, sensor in enumerate(sensors):
            heading = float(rng.uniform(-np.pi, np.pi))
            pose = np.array([positions[k, 0], positions[k, 1], heading])
            scan = sensor.scan(k, float(step), tuple(pose), no_discs, -1)
            team.add_scan(k, (k, step), scan.ranges, scan.angles, pose, scan.range_max_m)
        values = team.global_grid.to_occupancy_values()
        robot_cells = world.spec.world_to_cell(positions)
        t0 = time.perf_counter()
        got = detector.update(values, robot_cells, robot_cells)
        t1 = time.perf_counter()
        expected = reachable_frontier_cells(values, robot_cells)
        t2 = time.perf_counter()
        got_sorted = got[np.lexsort((got[:, 1], got[:, 0]))]
        assert np.array_equal(got_sorted, expected), f"frontier sets differ at step {step}"
        if step > 0:  # the first update is the full initial BFS
            ewfd_s.append(t1 - t0)
            naive_s.append(t2 - t1)
        frontier_counts.append(len(expected))
    ewfd_ms = 1e3 * statistics.mean(ewfd_s)
    naive_ms = 1e3 * statistics.mean(naive_s)
    print(f"frontiers: thesis world 4, {world.spec.rows}x{world.spec.cols}, 3 robots, ")
    print(
        f"  {ROUNDS} rounds of 3 scans, identical sets at every step "
        f"(frontier cells: median {int(np.median(frontier_counts))}, max {max(frontier_counts)})"
    )
    print(
        f"  EWFD incremental  mean {ewfd_ms:7.3f} ms/update (median "
        f"{1e3 * statistics.median(ewfd_s):.3f}, max {1e3 * max(ewfd_s):.3f})"
    )
    print(
        f"  naive full scan   mean {naive_ms:7.3f} ms/update (median "
        f"{1e3 * statistics.median(naive_s):.3f})"
    )
    print(f"  speed-up          {naive_ms / ewfd_ms:7.1f}x (goal >= 10x)")
    return world, values, robot_cells, got


def _timed_ms(call: Callable[[], object], repeats: int = 3) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        call()
        runs.append(time.perf_counter() - t0)
    return 1e3 * min(runs)


def bench_clustering_and_allocation(
    world: World, values: np.ndarray, frontier: np.ndarray, ref_ms: float
) -> None:
    spec = world.spec
    costmap = compute_costmap(values, spec, CostmapConfig(), RobotsConfig().radius_m)
    exploration = ExplorationConfig()
    clusters = cluster_frontiers(frontier, values, spec, costmap, exploration)
    dbscan_ms = _timed_ms(lambda: cluster_frontiers(frontier, values, spec, costmap, exploration))
    print(
        f"clustering: {len(frontier)} frontier cells -> {len(clusters)} clusters: "
        f"{dbscan_ms:.2f} ms ({dbscan_ms / ref_ms:.2f} ref)"
    )
    # 20 clusters: the real ones plus single-cell clusters at random reachable free cells.
    rng = np.random.default_rng(1)
    reachable = np.argwhere((values == 0) & ~costmap.lethal)
    extra = reachable[rng.choice(len(reachable), 20, replace=False)]
    clusters = (
        clusters
        + [
            FrontierCluster(
                cell[None, :],
                spec.cell_to_world(cell)[0],
                cell,
                spec.cell_to_world(cell)[0],
                int(rng.integers(5, 60)),
                0,
            )
            for cell in extra
        ]
    )[:20]
    print("allocation, 20 clusters, ms [x ref]; all but 'solve' include one Dijkstra per robot:")
    print(
        f"  {'robots':>6}  {'factor-graph':>22}  {'solve':>14}  {'hungarian':>14}  "
        f"{'greedy':>14}  {'thesis':>14}"
    )
    for robots in (3, 5, 8):
        cells = reachable[rng.choice(len(reachable), robots, replace=False)]
        row = [f"  {robots:6d}"]
        for method in ("factor-graph", "hungarian", "greedy", "thesis"):
            config = AllocationConfig(method=method)
            result = allocate(cells, clusters, costmap, config)
            ms = _timed_ms(partial(allocate, cells, clusters, costmap, config))
            row.append(f"{ms:7.2f} [{ms / ref_ms:4.2f}]")
            if method == "factor-graph":
                row[-1] = f"{row[-1]} {result.solver:>8}"
                sizes = np.array([c.size_cells for c in clusters], dtype=float)
                unary = unary_log_factors(result.distances_m, sizes, config.alpha, config.beta)
                solve = solve_exact if result.solver == "exact" else solve_approximate
                ms = _timed_ms(partial(solve, unary, config.conflict_lambda))
                row.append(f"{ms:7.2f} [{ms / ref_ms:4.2f}]")
        print("  ".join(row))


def reference_ms() -> float:
    data = np.random.default_rng(0).random((800, 800))
    runs = []
    for _ in range(5):
        t0 = time.perf_counter()
        np.sort(data, axis=1)
        runs.append(time.perf_counter() - t0)
    return 1e3 * min(runs)


def main() -> None:
    ref_ms = reference_ms()
    print(f"reference (np.sort of 800x800 float64 rows): {ref_ms:.2f} ms")
    world, values, _, frontier = bench_frontiers()
    bench_clustering_and_allocation(world, values, frontier, ref_ms)


if __name__ == "__main__":
    main()
