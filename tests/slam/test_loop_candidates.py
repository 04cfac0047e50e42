"""The loop-closure candidate index against the exhaustive search it replaces (the
benchmark's reference: scipy's cKDTree over all keyframes, as the search was before)."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.benchmarks.loop_closure import ExhaustiveSearch, measure_loop_candidate_search
from acslam.slam.loop_candidates import LoopCandidates

RADIUS_M = 2.0
SEPARATION_S = 20.0
ATTEMPTS = 3


def _exhaustive(robots: np.ndarray, stamps_s: np.ndarray) -> ExhaustiveSearch:
    return ExhaustiveSearch(robots, stamps_s, RADIUS_M, SEPARATION_S, ATTEMPTS)


def _layout(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n keyframes of 3 robots, 1 s apart per robot, uniformly in a 20 m square."""
    robots = rng.integers(0, 3, n)
    stamps_s = np.zeros(n)
    for r in range(3):
        stamps_s[robots == r] = np.arange((robots == r).sum(), dtype=float)
    return rng.uniform(0.0, 20.0, (n, 2)), robots, stamps_s


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_pairs_in_the_same_order_as_the_exhaustive_search(seed: int) -> None:
    """Keyframes arrive in batches; between searches all creep (less than the slack, so
    they stay at their anchors), some jump up to metres (a loop closure): after every step
    the index tries exactly the exhaustive search's pairs, in its order."""
    rng = np.random.default_rng(seed)
    positions, robots, stamps_s = _layout(rng, 600)
    index = LoopCandidates(RADIUS_M, SEPARATION_S, ATTEMPTS, slack_m=0.1)
    reference = _exhaustive(robots, stamps_s)
    count = tried = 0
    for _ in range(15):
        for _k in range(40):
            index.add(int(robots[count]), float(stamps_s[count]))
            count += 1
        now = positions[:count]
        now += rng.normal(scale=0.004, size=now.shape)  # everyone creeps
        jump = rng.random(count) < 0.05
        now[jump] += rng.normal(scale=rng.choice([0.06, 1.5]), size=(int(jump.sum()), 2))
        chosen = index.search(now, now.__getitem__)
        assert chosen == reference.search(now)
        tried += len(chosen)
    assert tried > 500


def test_positions_within_the_tolerance_give_the_exact_answer() -> None:
    """The positions that decide where keyframes sit may be off by up to tolerance_m;
    distances and order come from the exact positions alone."""
    rng = np.random.default_rng(3)
    exact, robots, stamps_s = _layout(rng, 400)
    index = LoopCandidates(RADIUS_M, SEPARATION_S, ATTEMPTS, slack_m=0.1, tolerance_m=1e-3)
    reference = _exhaustive(robots, stamps_s)
    for r, s in zip(robots, stamps_s, strict=True):
        index.add(int(r), float(s))
    for _ in range(5):
        exact = exact + rng.normal(scale=0.01, size=exact.shape)
        rough = exact + rng.uniform(-7e-4, 7e-4, exact.shape)  # |error| <= 1e-3 m
        chosen = index.search(rough, exact.__getitem__)
        assert chosen == reference.search(exact)
    assert len(reference.tried) > 500


def test_a_search_measures_only_what_moved_and_what_is_near() -> None:
    """A place passed many times: once its pairs were tried, a search after everyone
    crept less than half the slack measures only the few keyframes that may still be
    tried and their kept neighbours, not the thousand keyframes there."""
    rng = np.random.default_rng(4)
    count = 1000
    robots = np.arange(count) % 3
    stamps_s = np.arange(count) * 1.0
    positions = rng.uniform(0.0, 6.0, (count, 2))  # 28 keyframes per m^2
    index = LoopCandidates(RADIUS_M, SEPARATION_S, ATTEMPTS, slack_m=0.1)
    reference = _exhaustive(robots, stamps_s)
    for r, s in zip(robots, stamps_s, strict=True):
        index.add(int(r), float(s))
    assert index.search(positions, positions.__getitem__) == reference.search(positions)
    measured: set[int] = set()

    def exact(k: int) -> np.ndarray:
        measured.add(k)
        return positions[k]

    positions = positions + rng.uniform(-0.035, 0.035, positions.shape)  # < 0.05 m
    assert index.search(positions, exact) == reference.search(positions)
    assert len(measured) < 20


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="tolerance_m"):
        LoopCandidates(RADIUS_M, SEPARATION_S, ATTEMPTS, slack_m=0.1, tolerance_m=0.05)
    with pytest.raises(ValueError, match="attempts"):
        LoopCandidates(RADIUS_M, SEPARATION_S, 0)


def test_loop_search_benchmark_checks_itself_against_the_exhaustive_search() -> None:
    """The corridor benchmark on 600 keyframes: the robots share the corridor, so its
    searches try pairs across robots before any lap closes, and every 25th search is
    compared with the exhaustive search (the benchmark raises on any difference)."""
    result = measure_loop_candidate_search(keyframes=600, robots=3, seed=1)
    assert [b["searches"] for b in result["buckets"]] == [60]
    assert result["buckets"][0]["references"] == 2
    assert result["pairs_tried"] > 0
