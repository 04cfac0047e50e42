"""Planning benchmarks: our numba A* against a reference, the joint FGP per team size."""

from __future__ import annotations

import heapq
import importlib.util
import math
import time

import numba
import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from acslam.benchmarks.core import Figure
from acslam.config import PlanningConfig, RobotsConfig
from acslam.grid import GridSpec
from acslam.planning.astar import astar_cells, astar_expansions
from acslam.planning.fgp import FactorGraphPlanner
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.params import AstarParams, FgpParams
from acslam.sim.kinematics import limit_command, step_pose

RES_M = 0.05
RADIUS_M = RobotsConfig().radius_m


def _costmap(size: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random obstacle blobs, lethal within the robot radius, exponential-decay cost."""
    rng = np.random.default_rng(seed)
    occupied = ndimage.binary_dilation(rng.random((size, size)) < 0.002, iterations=6)
    distance_m = ndimage.distance_transform_edt(~occupied) * RES_M
    lethal = distance_m < RADIUS_M + RES_M
    return np.exp(-5.0 * np.maximum(distance_m - RADIUS_M, 0.0)), lethal


def _nearest_free(lethal: np.ndarray, cell: tuple[int, int]) -> tuple[int, int]:
    free = np.argwhere(~lethal)
    return tuple(int(v) for v in free[np.argmin(((free - cell) ** 2).sum(axis=1))])


def _scipy_dijkstra(weights: np.ndarray, start: tuple[int, int]) -> int:
    """Single-source Dijkstra over the same 8-connected grid graph (scipy's C code);
    returns how many cells it settled (every reachable one)."""
    rows, cols = weights.shape
    index = np.arange(rows * cols).reshape(rows, cols)
    sources, targets, lengths = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = index[max(0, -dr) : rows - max(0, dr), max(0, -dc) : cols - max(0, dc)]
        b = index[max(0, dr) : rows - max(0, -dr), max(0, dc) : cols - max(0, -dc)]
        step = math.hypot(dr, dc) * RES_M
        for u, v in ((a, b), (b, a)):
            w = step * weights.ravel()[v.ravel()]
            ok = np.isfinite(w)
            sources.append(u.ravel()[ok])
            targets.append(v.ravel()[ok])
            lengths.append(w[ok])
    graph = coo_matrix(
        (np.concatenate(lengths), (np.concatenate(sources), np.concatenate(targets))),
        shape=(rows * cols, rows * cols),
    ).tocsr()
    return int(np.isfinite(dijkstra(graph, indices=start[0] * cols + start[1])).sum())


@numba.njit(cache=True)
def pyastar2d_expansions(weights: np.ndarray, start: int, goal: int) -> tuple[int, float]:
    """pyastar2d's search replayed to count its expansions (it reports none): float32
    costs, entering a cell costs its weight on straight and diagonal steps alike, the
    L-inf heuristic, corners cut, and no closed set, so every pop is expanded. Returns
    (cells expanded, the goal's cost); the cost matches the length of pyastar2d's own path
    up to float32 rounding, and the count up to the order of equal keys."""
    rows, cols = weights.shape
    flat = weights.ravel()
    costs = np.full(rows * cols, np.inf, dtype=np.float32)
    costs[start] = 0.0
    goal_r, goal_c = goal // cols, goal % cols
    heap = [(np.float32(0.0), start)]
    expanded = 0
    while heap:
        node = heapq.heappop(heap)[1]
        if node == goal:
            break
        expanded += 1
        r, c = node // cols, node % cols
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                nr, nc = r + dr, c + dc
                if (dr == 0 and dc == 0) or nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                    continue
                nxt = nr * cols + nc
                new_cost = np.float32(costs[node] + flat[nxt])
                if new_cost < costs[nxt]:
                    costs[nxt] = new_cost
                    h = np.float32(max(abs(nr - goal_r), abs(nc - goal_c)))
                    heapq.heappush(heap, (np.float32(new_cost + h), nxt))
    return expanded, float(costs[goal])


def bench_astar(quick: bool) -> list[Figure]:
    """Corner-to-corner A* queries on random costmaps against pyastar2d on the same weights.

    Without the ``bench`` extra (pyastar2d) the reference is scipy's single-source
    Dijkstra on the same 8-connected graph, which expands every cell: a weaker yardstick,
    named as such in the figure. pyastar2d charges diagonal steps like straight ones and
    cuts corners, so its searches expand other cells than ours: the second figure divides
    each search's expansions by its time, ours counted by our search, pyastar2d's by
    :func:`pyastar2d_expansions` (scipy's: every reachable cell).
    """
    size = 400 if quick else 800
    weight = AstarParams().cost_weight
    has_pyastar = importlib.util.find_spec("pyastar2d") is not None
    queries = [((5, 5), (size - 10, size - 10)), ((5, size - 10), (size - 10, 5))]
    cost, lethal = _costmap(size, 0)
    astar_cells(
        cost, lethal, _nearest_free(lethal, (5, 5)), _nearest_free(lethal, (9, 9)), RES_M, weight
    )
    ours, theirs, our_cells, their_cells = [], [], [], []
    for seed in range(2 if quick else 3):
        cost, lethal = _costmap(size, seed)
        weights = (1.0 + weight * cost).astype(np.float32)
        weights[lethal] = np.inf
        for a, b in queries:
            start, goal = _nearest_free(lethal, a), _nearest_free(lethal, b)
            t0 = time.perf_counter()
            astar_cells(cost, lethal, start, goal, RES_M, weight)
            ours.append(time.perf_counter() - t0)
            our_cells.append(astar_expansions(cost, lethal, start, goal, RES_M, weight))
            if has_pyastar:
                import pyastar2d

                t0 = time.perf_counter()
                pyastar2d.astar_path(weights, start, goal, allow_diagonal=True)
                theirs.append(time.perf_counter() - t0)
                flat_start, flat_goal = start[0] * size + start[1], goal[0] * size + goal[1]
                their_cells.append(pyastar2d_expansions(weights, flat_start, flat_goal)[0])
            else:
                t0 = time.perf_counter()
                their_cells.append(_scipy_dijkstra(weights, start))
                theirs.append(time.perf_counter() - t0)
    reference = "pyastar2d, same queries" if has_pyastar else "scipy Dijkstra (no pyastar2d)"
    return [
        Figure(
            "planning",
            f"A* {size}x{size}, corner to corner ({len(ours)} queries, median)",
            1e3 * float(np.median(ours)),
            "ms",
            reference,
            1e3 * float(np.median(theirs)),
        ),
        Figure(
            "planning",
            f"A* {size}x{size} cells expanded per second (same queries, median)",
            1e-6 * float(np.median(np.divide(our_cells, ours))),
            "M cells/s",
            reference,
            1e-6 * float(np.median(np.divide(their_cells, theirs))),
            f"higher is faster; expanded per query: ours {np.median(our_cells):,.0f}, "
            f"reference {np.median(their_cells):,.0f}",
        ),
    ]


def bench_fgp(quick: bool) -> list[Figure]:
    """Joint FGP solve time per team size: robots on a 2 m circle cross through its centre.

    The reference is the one-robot solve measured the same way; the note gives the share
    of the 100 ms control period each solve takes.
    """
    planning, robots = PlanningConfig(), RobotsConfig()
    field = DistanceField(np.full((200, 200), 10.0), GridSpec(-5.0, -5.0, RES_M, 200, 200))
    cycles = 15 if quick else 100
    figures, base_ms = [], 0.0
    for count in (1, 2, 4, 8) if quick else range(1, 9):
        angles = 2 * math.pi * np.arange(count) / count
        poses = [(2.0 * math.cos(a), 2.0 * math.sin(a), a + math.pi) for a in angles]
        goals = [np.array([-p[0], -p[1]]) for p in poses]
        velocities = [(0.0, 0.0)] * count
        planner = FactorGraphPlanner(FgpParams(), planning=planning, robots=robots)
        times = []
        for _ in range(cycles):
            states = [RobotState(*p, *v) for p, v in zip(poses, velocities, strict=True)]
            reach = planning.horizon_s * robots.max_v_mps
            lookahead = []
            for state, goal in zip(states, goals, strict=True):
                gap = goal - state.xy_m
                norm = float(np.linalg.norm(gap))
                lookahead.append(goal if norm <= reach else state.xy_m + gap * reach / norm)
            t0 = time.perf_counter()
            result = planner.solve(states, lookahead, field)
            times.append(time.perf_counter() - t0)
            for r, (v, w) in enumerate(result.commands):
                for _ in range(5):
                    velocities[r] = limit_command(v, w, *velocities[r], robots, 0.02)
                    poses[r] = step_pose(*poses[r], *velocities[r], 0.02)
        mean_ms = 1e3 * float(np.mean(times[1:]))
        base_ms = base_ms or mean_ms
        period_ms = 1e3 * planning.control_period_s
        figures.append(
            Figure(
                "planning",
                f"FGP joint solve, {count} robot{'s' if count > 1 else ''}",
                mean_ms,
                "ms",
                "FGP, 1 robot",
                base_ms,
                f"{100 * mean_ms / period_ms:.0f} % of the control period; p95 "
                f"{1e3 * np.percentile(times[1:], 95):.1f} ms",
            )
        )
    return figures
