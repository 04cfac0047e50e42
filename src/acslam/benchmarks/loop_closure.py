"""Loop-closure candidate search against graph size: the index of
:mod:`acslam.slam.loop_candidates` and the search over all keyframes it replaced, timed
in the same process on the same keyframe positions.

Three robots drive laps of one rectangular corridor (40 m x 25 m, a keyframe every
0.3 m, 0.6 s apart), a little apart across it, so every lap passes the earlier laps'
keyframes: the loop-driving phase of a long run, where the pairs within the radius grow
with every lap. Between searches every keyframe creeps (0.2 mm, as SLAM moves them at
every update) and now and then a robot's last 100 keyframes jump a few centimetres (a
loop closure). A search follows every ten keyframes; the tried pairs and the attempt cap
are those of :class:`~acslam.slam.lidar_constraints.LidarConstraints`. The exhaustive
search (scipy's cKDTree over all keyframes, then the untried pairs, nearest first) runs
beside it every 25th search, on the same state, and must lead to the same pairs tried.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from acslam.benchmarks.core import spread_ms
from acslam.config import ScanMatchingConfig
from acslam.slam.lidar_constraints import MAX_LOOP_ATTEMPTS
from acslam.slam.loop_candidates import LoopCandidates

LAP_M = (40.0, 25.0)
STEP_M = 0.3
STEP_S = 0.6
SEARCH_EVERY = 10
REFERENCE_EVERY = 25
BUCKET = 1000


def _lap_position(distance_m: float, lane_m: float) -> np.ndarray:
    """Point ``distance_m`` along the rectangle's perimeter, ``lane_m`` inside it."""
    width, height = LAP_M[0] - 2 * lane_m, LAP_M[1] - 2 * lane_m
    s = distance_m % (2 * (width + height))
    for length, start, direction in (
        (width, (0.0, 0.0), (1.0, 0.0)),
        (height, (width, 0.0), (0.0, 1.0)),
        (width, (width, height), (-1.0, 0.0)),
        (height, (0.0, height), (0.0, -1.0)),
    ):
        if s <= length:
            return np.array(start) + s * np.array(direction) + lane_m
        s -= length
    return np.array([lane_m, lane_m])


class ExhaustiveSearch:
    """The search over all keyframes that :class:`LoopCandidates` replaced: every pair
    within the radius (scipy's cKDTree), not neighbours in time, not tried, nearest first
    (ties by pair), at most ``attempts`` per later keyframe."""

    def __init__(
        self,
        robots: np.ndarray,
        stamps_s: np.ndarray,
        radius_m: float,
        min_separation_s: float,
        attempts: int,
    ) -> None:
        self.robots, self.stamps_s = robots, stamps_s
        self.radius_m, self.min_separation_s, self.attempts = radius_m, min_separation_s, attempts
        self.tried: set[tuple[int, int]] = set()
        self.tries: dict[int, int] = {}

    def search(self, positions: np.ndarray) -> list[tuple[int, int]]:
        """The pairs to try among the first len(positions) keyframes; they count as tried."""
        pairs = cKDTree(positions).query_pairs(self.radius_m, output_type="ndarray")
        found = []
        for i, j in sorted(map(tuple, pairs.tolist())):
            same = self.robots[i] == self.robots[j]
            if same and abs(self.stamps_s[i] - self.stamps_s[j]) < self.min_separation_s:
                continue
            if (i, j) not in self.tried:
                found.append((float(np.hypot(*(positions[i] - positions[j]))), (i, j)))
        chosen = []
        for _, pair in sorted(found):
            if self.tries.get(pair[1], 0) < self.attempts:
                self.tries[pair[1]] = self.tries.get(pair[1], 0) + 1
                self.tried.add(pair)
                chosen.append(pair)
        return chosen


def measure_loop_candidate_search(keyframes: int, robots: int, seed: int) -> dict:
    """Grow the corridor run to ``keyframes`` keyframes, timing every search.

    Returns ``{"keyframes", "robots", "seed", "buckets": [{"from", "to", "searches",
    "index_mean_ms", "index_p95_ms", "exhaustive_mean_ms", "references"}], "pairs_tried"}``
    per bucket of 1000 keyframes.
    """
    if keyframes < 1 or robots < 1:
        raise ValueError("keyframes and robots must be >= 1")
    rng = np.random.default_rng(seed)
    config = ScanMatchingConfig()
    args = (config.loop_radius_m, config.loop_min_separation_s, MAX_LOOP_ATTEMPTS)
    index = LoopCandidates(*args)
    positions = np.zeros((keyframes, 2))
    robot_of = np.arange(keyframes) % robots
    stamps_s = (np.arange(keyframes) // robots) * STEP_S
    start_m = rng.uniform(0.0, 2 * sum(LAP_M), robots)
    lanes_m = 1.0 + 0.4 * np.arange(robots)
    timings: list[tuple[int, float, float | None]] = []
    tried = 0
    for count in range(1, keyframes + 1):
        k = count - 1
        r = int(robot_of[k])
        positions[k] = _lap_position(start_m[r] + STEP_M * (k // robots), lanes_m[r])
        index.add(r, float(stamps_s[k]))
        if count % SEARCH_EVERY:
            continue
        now = positions[:count]
        now += rng.normal(scale=2e-4, size=now.shape)
        if rng.random() < 0.05:
            last = np.flatnonzero(robot_of[:count] == rng.integers(robots))[-100:]
            now[last] += rng.normal(scale=0.05, size=2)
        reference = None
        if (count // SEARCH_EVERY) % REFERENCE_EVERY == 0:
            # The exhaustive search, from the same tried pairs and attempts.
            reference = ExhaustiveSearch(robot_of, stamps_s, *args)
            reference.tried, reference.tries = set(index._tried), dict(index._tries)
        started = time.perf_counter()
        chosen = index.search(now, now.__getitem__)
        index_s = time.perf_counter() - started
        tried += len(chosen)
        reference_s = None
        if reference is not None:
            started = time.perf_counter()
            if reference.search(now) != chosen:
                raise AssertionError(f"index and exhaustive search differ at {count} keyframes")
            reference_s = time.perf_counter() - started
        timings.append((count, index_s, reference_s))
    buckets = []
    for start in range(0, keyframes, BUCKET):
        rows = [t for t in timings if start < t[0] <= start + BUCKET]
        if not rows:
            continue
        index_ms = 1e3 * np.array([t[1] for t in rows])
        reference_ms = 1e3 * np.array([t[2] for t in rows if t[2] is not None])
        buckets.append(
            {
                "from": start,
                "to": min(start + BUCKET, keyframes),
                "searches": len(rows),
                **spread_ms(index_ms, "index_"),
                "exhaustive_mean_ms": float(reference_ms.mean()) if len(reference_ms) else None,
                "references": len(reference_ms),
            }
        )
    return {
        "keyframes": keyframes,
        "robots": robots,
        "seed": seed,
        "buckets": buckets,
        "pairs_tried": tried,
    }
