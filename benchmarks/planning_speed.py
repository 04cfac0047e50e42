"""Planning speed: our numba A* vs pyastar2d, and FGP solve time vs team size.

Run: ``python benchmarks/planning_speed.py`` (needs ``pip install pyastar2d``), or
``python benchmarks/planning_speed.py --fgp-only`` for the FGP figures alone.

pyastar2d charges the entered cell's weight for diagonal steps too (no sqrt(2)), uses
the L-inf heuristic and cuts corners, so its paths differ from ours: the figure compares
speed on the same costmaps, with weights ``1 + w * cost`` and inf on lethal cells.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
import pyastar2d
from scipy import ndimage

from acslam.config import PlanningConfig, RobotsConfig
from acslam.grid import GridSpec
from acslam.planning.astar import astar_cells, distances_from
from acslam.planning.fgp import FactorGraphPlanner
from acslam.planning.field import DistanceField, RobotState
from acslam.sim.kinematics import limit_command, step_pose

RES_M = 0.05
SIZE = 800
RADIUS_M = RobotsConfig().radius_m


def costmap(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random obstacle blobs, lethal within the robot radius, exponential-decay cost."""
    rng = np.random.default_rng(seed)
    occupied = ndimage.binary_dilation(rng.random((SIZE, SIZE)) < 0.002, iterations=6)
    distance_m = ndimage.distance_transform_edt(~occupied) * RES_M
    lethal = distance_m < RADIUS_M + RES_M
    cost = np.exp(-5.0 * np.maximum(distance_m - RADIUS_M, 0.0))
    return cost, lethal


def nearest_free(lethal: np.ndarray, cell: tuple[int, int]) -> tuple[int, int]:
    free = np.argwhere(~lethal)
    return tuple(int(v) for v in free[np.argmin(((free - cell) ** 2).sum(axis=1))])


def bench_astar(weight: float) -> None:
    ours, theirs = [], []
    queries = [((5, 5), (790, 790)), ((5, 790), (790, 5)), ((400, 5), (400, 790))]
    cost, lethal = costmap(0)
    astar_cells(
        cost, lethal, nearest_free(lethal, (5, 5)), nearest_free(lethal, (9, 9)), RES_M, weight
    )  # compile
    for seed in range(3):
        cost, lethal = costmap(seed)
        weights = (1.0 + weight * cost).astype(np.float32)
        weights[lethal] = np.inf
        for a, b in queries:
            start, goal = nearest_free(lethal, a), nearest_free(lethal, b)
            t0 = time.perf_counter()
            astar_cells(cost, lethal, start, goal, RES_M, weight)
            t1 = time.perf_counter()
            pyastar2d.astar_path(weights, start, goal, allow_diagonal=True)
            t2 = time.perf_counter()
            ours.append(t1 - t0)
            theirs.append(t2 - t1)
    t0 = time.perf_counter()
    distances_from(cost, lethal, nearest_free(lethal, (400, 400)), RES_M, weight)
    dijkstra_s = time.perf_counter() - t0
    ratio = statistics.median(o / t for o, t in zip(ours, theirs, strict=True))
    print(
        f"A* 800x800, w={weight}: ours median {1e3 * statistics.median(ours):.1f} ms, "
        f"pyastar2d {1e3 * statistics.median(theirs):.1f} ms, median ratio {ratio:.2f}x "
        f"({len(ours)} queries); Dijkstra to all cells {1e3 * dijkstra_s:.1f} ms"
    )


def bench_fgp() -> None:
    """Robots on a 2 m circle drive to the opposite point, so all meet in the middle."""
    planning, robots = PlanningConfig(), RobotsConfig()
    grid = GridSpec(-5.0, -5.0, RES_M, 200, 200)
    field = DistanceField(np.full(grid.shape, 10.0), grid)
    base_ms = None
    print(f"FGP, N = {planning.horizon_steps}, 150 cycles (15 s) of a crossing through one point:")
    for count in (1, 3, 6, 10):
        angles = 2 * math.pi * np.arange(count) / count
        poses = [(2.0 * math.cos(a), 2.0 * math.sin(a), a + math.pi) for a in angles]
        goals = [np.array([-p[0], -p[1]]) for p in poses]
        velocities = [(0.0, 0.0)] * count
        planner = FactorGraphPlanner(planning, robots)
        times, solves = [], []
        for _ in range(150):
            states = [RobotState(*p, *v) for p, v in zip(poses, velocities, strict=True)]
            lookahead = []
            for s, g in zip(states, goals, strict=True):
                gap = g - s.xy_m
                reach = planning.horizon_s * robots.max_v_mps
                norm = float(np.linalg.norm(gap))
                lookahead.append(g if norm <= reach else s.xy_m + gap * reach / norm)
            t0 = time.perf_counter()
            result = planner.plan(states, lookahead, field)
            times.append(time.perf_counter() - t0)
            solves.append(result.iterations)
            for r, (v, w) in enumerate(result.commands):
                for _ in range(5):
                    velocities[r] = limit_command(v, w, *velocities[r], robots, 0.02)
                    poses[r] = step_pose(*poses[r], *velocities[r], 0.02)
        ms = 1e3 * np.array(times)
        median = float(np.median(ms))
        base_ms = base_ms or median
        print(
            f"  {count:2d} robot(s): mean {ms.mean():6.2f}  median {median:6.2f}  "
            f"p95 {np.percentile(ms, 95):6.2f}  max {ms.max():6.2f} ms/cycle, "
            f"median ratio vs 1 robot {median / base_ms:5.1f}x, "
            f"{statistics.mean(solves):.1f} LM solves/cycle"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fgp-only", action="store_true", help="skip the A* comparison")
    if not parser.parse_args().fgp_only:
        bench_astar(PlanningConfig().astar_cost_weight)
        bench_astar(0.0)
    bench_fgp()
