"""Global correlative matching: the pyramid bounds, branch and bound against the
exhaustive search it must equal, and poses recovered from simulated scans."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from acslam.config import LidarConfig, ThesisWorld
from acslam.geometry import wrap_angle
from acslam.grid import FREE, OCCUPIED, GridSpec
from acslam.mapping.correlative import (
    HeadingTable,
    LikelihoodPyramid,
    SearchWindow,
    angle_step_rad,
    best_match,
    block_maxima,
    exhaustive_match,
)
from acslam.sim.lidar import beam_angles, cast_scan
from acslam.worlds.mapio import world_cells
from acslam.worlds.thesis import thesis_world


def test_each_level_is_the_maximum_of_its_block() -> None:
    rng = np.random.default_rng(0)
    field = rng.random((37, 23)).astype(np.float32)
    levels = block_maxima(field, 4)
    pad = 15  # blocks may start up to 2^4 - 1 cells before the grid
    assert levels.shape == (5, pad + 37, pad + 23)
    for h in range(5):
        side = 1 << h
        for r in range(-pad, 37):
            for c in range(-pad, 23):
                block = field[max(r, 0) : max(r + side, 0), max(c, 0) : max(c + side, 0)]
                expected = block.max() if block.size else 0.0
                assert levels[h, pad + r, pad + c] == expected


def _random_map(rng: np.random.Generator) -> tuple[np.ndarray, GridSpec]:
    """A 3 m x 3 m room at 0.05 m with a few random wall segments inside."""
    spec = GridSpec(0.0, 0.0, 0.05, 60, 60)
    values = np.full(spec.shape, FREE, dtype=np.int8)
    values[[0, -1], :] = OCCUPIED
    values[:, [0, -1]] = OCCUPIED
    for _ in range(4):
        r, c = rng.integers(5, 55, size=2)
        length = int(rng.integers(5, 20))
        if rng.random() < 0.5:
            values[r, c : c + length] = OCCUPIED
        else:
            values[r : r + length, c] = OCCUPIED
    return values, spec


@pytest.mark.parametrize(("seed", "count"), [*((s, 80) for s in range(6)), (6, 1200), (7, 1200)])
def test_branch_and_bound_returns_what_the_exhaustive_search_returns(seed: int, count: int) -> None:
    """With more than SEED_POINTS points, the search starts from a subsample's answer:
    it must still return the exhaustive search's."""
    rng = np.random.default_rng(seed)
    values, spec = _random_map(rng)
    pyramid = LikelihoodPyramid.from_occupancy(values, spec, sigma_m=0.08, depth=3)
    occupied = np.argwhere(values == OCCUPIED)
    picked = spec.cell_to_world(occupied[rng.choice(len(occupied), count, replace=count > 80)])
    truth = np.array([1.5, 1.5, 0.0]) + rng.uniform([-0.2, -0.2, -0.2], [0.2, 0.2, 0.2])
    # The points in the frame of ``truth``, with 2 cm of noise.
    c, s = math.cos(truth[2]), math.sin(truth[2])
    local = (picked - truth[:2]) @ np.array([[c, -s], [s, c]])
    local += rng.normal(0.0, 0.02, local.shape)
    window = SearchWindow.around(np.array([1.5, 1.5, 0.0]), local, 0.35, 0.3)
    fast = best_match(local, pyramid, window)
    slow = exhaustive_match(local, pyramid, window)
    assert fast is not None and slow is not None
    assert fast.score == slow.score
    np.testing.assert_allclose(fast.pose, slow.pose)
    # The best pose other than that one, 0.3 m or 0.1 rad away: the same again.
    kwargs = {"excluded": (fast,), "excluded_radius_m": 0.3, "excluded_angle_rad": 0.1}
    fast_other = best_match(local, pyramid, window, **kwargs)
    slow_other = exhaustive_match(local, pyramid, window, **kwargs)
    assert fast_other is not None and slow_other is not None
    assert fast_other.score == slow_other.score < fast.score
    np.testing.assert_allclose(fast_other.pose, slow_other.pose)
    # And the best outside both: blocks wholly inside either zone are pruned unsearched.
    kwargs = {**kwargs, "excluded": (fast, fast_other)}
    fast_third = best_match(local, pyramid, window, **kwargs)
    slow_third = exhaustive_match(local, pyramid, window, **kwargs)
    assert fast_third is not None and slow_third is not None
    assert fast_third.score == slow_third.score <= fast_other.score
    np.testing.assert_allclose(fast_third.pose, slow_third.pose)


@dataclass(frozen=True)
class _PinnedCase:
    """Points of a random room seen from ``truth``; the robot stands at ``robot_local``
    in the points' frame, and a teammate saw it at ``seen`` (0.1 m off): the window
    pinned 0.25 m about it."""

    local: np.ndarray
    pyramid: LikelihoodPyramid
    window: SearchWindow
    robot_local: np.ndarray
    seen: np.ndarray
    truth: np.ndarray
    resolution_m: float


def _pinned_case(seed: int) -> _PinnedCase:
    rng = np.random.default_rng(seed)
    values, spec = _random_map(rng)
    pyramid = LikelihoodPyramid.from_occupancy(values, spec, sigma_m=0.08, depth=3)
    occupied = np.argwhere(values == OCCUPIED)
    picked = spec.cell_to_world(occupied[rng.choice(len(occupied), 150, replace=False)])
    truth = np.array([*rng.uniform(1.0, 2.0, 2), rng.uniform(-math.pi, math.pi)])
    c, s = math.cos(truth[2]), math.sin(truth[2])
    local = (picked - truth[:2]) @ np.array([[c, -s], [s, c]])
    robot_local = rng.uniform(-1.0, 1.0, 2)
    seen = truth[:2] + np.array([[c, -s], [s, c]]) @ robot_local + rng.uniform(-0.1, 0.1, 2)
    window = SearchWindow.pinned(robot_local, seen, 0.25)
    return _PinnedCase(local, pyramid, window, robot_local, seen, truth, spec.resolution_m)


@pytest.mark.parametrize("seed", range(4))
def test_a_window_pinned_on_a_point_holds_that_point_and_equals_the_exhaustive_search(
    seed: int,
) -> None:
    """A teammate saw the robot at ``seen``: only poses that put the robot's place near it,
    at every heading, are searched, and branch and bound still returns the exhaustive
    search's pose, which puts the robot within the window."""
    case = _pinned_case(seed)
    fast = best_match(case.local, case.pyramid, case.window)
    slow = exhaustive_match(case.local, case.pyramid, case.window)
    assert fast is not None and slow is not None
    assert fast.score == slow.score
    np.testing.assert_allclose(fast.pose, slow.pose)
    placed_robot = fast.pose[:2] + np.array(
        [[math.cos(fast.pose[2]), -math.sin(fast.pose[2])],
         [math.sin(fast.pose[2]), math.cos(fast.pose[2])]]
    ) @ case.robot_local  # fmt: skip
    assert np.all(np.abs(placed_robot - case.seen) <= 0.25 + case.resolution_m)
    assert np.linalg.norm(fast.pose[:2] - case.truth[:2]) <= 2 * case.resolution_m
    assert abs(wrap_angle(fast.pose[2] - case.truth[2])) <= 2 * fast.angle_step_rad


@pytest.mark.parametrize("seed", range(4))
def test_the_heading_table_answers_a_merges_questions_as_the_exhaustive_search_does(
    seed: int,
) -> None:
    """The best pose, then the best outside zones of 0.5 m (wider than the window) or
    0.3 rad about each pose found, five times, then the best above a share of the first
    score: each the exhaustive search's score and pose."""
    case = _pinned_case(seed)
    local, pyramid, window = case.local, case.pyramid, case.window
    table = HeadingTable(local, pyramid, window)
    found: tuple = ()
    for _ in range(6):
        kwargs = {"excluded": found, "excluded_radius_m": 0.5, "excluded_angle_rad": 0.3}
        fast = table.best(**kwargs)
        slow = exhaustive_match(local, pyramid, window, **kwargs)
        assert fast is not None and slow is not None
        assert fast.score == slow.score
        np.testing.assert_allclose(fast.pose, slow.pose)
        found = (*found, fast)
    # Each later answer lies outside the earlier ones' zones, so no better than they.
    scores = [m.score for m in found]
    assert scores == sorted(scores, reverse=True) and len(set(scores)) > 1
    above = table.best(0.99 * scores[0], found[:1], 0.5, 0.3)
    assert above is None or above.score > 0.99 * scores[0]
    assert table.best(scores[0]) is None


def test_a_zone_narrower_than_the_window_is_searched_by_branch_and_bound() -> None:
    """A zone of one leaf leaves the rest of the window at its heading: the table alone
    cannot say what lies there (here the next best pose: the same heading, a cell over),
    so the answer comes from the full search."""
    case = _pinned_case(4)
    local, pyramid, window = case.local, case.pyramid, case.window
    table = HeadingTable(local, pyramid, window)
    first = table.best()
    assert first is not None
    kwargs = {"excluded": (first,), "excluded_radius_m": 0.0, "excluded_angle_rad": 0.0}
    other, reference = table.best(**kwargs), exhaustive_match(local, pyramid, window, **kwargs)
    assert other is not None and reference is not None
    assert reference.pose[2] == pytest.approx(first.pose[2])
    assert other.score == reference.score
    np.testing.assert_allclose(other.pose, reference.pose)


def test_a_minimum_score_above_the_best_finds_nothing() -> None:
    values, spec = _random_map(np.random.default_rng(1))
    pyramid = LikelihoodPyramid.from_occupancy(values, spec, sigma_m=0.08, depth=3)
    points = spec.cell_to_world(np.argwhere(values == OCCUPIED)[::7])
    window = SearchWindow.around(np.zeros(3), points, 0.2, 0.1)
    best = best_match(points, pyramid, window)
    assert best is not None
    assert best_match(points, pyramid, window, min_score=best.score) is None


def test_angle_step_moves_the_farthest_point_by_one_cell() -> None:
    step = angle_step_rad(0.05, 8.0)
    chord = 2 * 8.0 * math.sin(step / 2)  # how far a turn by step moves a point at 8 m
    assert chord == pytest.approx(0.05, rel=1e-9)


def _scan_points(world, pose: tuple[float, float, float], rng) -> np.ndarray:
    """One LDS-02 scan (1.5 % range noise) at ``pose``, as points in the robot frame."""
    config = LidarConfig()
    angles = beam_angles(config)
    ranges = cast_scan(
        world.occupied, world.spec.origin_x_m, world.spec.origin_y_m, world.spec.resolution_m,
        *pose, angles, rng.standard_normal(len(angles)), rng.standard_normal(len(angles)),
        np.zeros((0, 3)), -1,
        np.array([config.range_min_m, config.range_max_m, 0.0, 0.015, 0.0]),
    )  # fmt: skip
    ok = np.isfinite(ranges) & (ranges > 0)
    return np.column_stack([ranges[ok] * np.cos(angles[ok]), ranges[ok] * np.sin(angles[ok])])


@pytest.mark.parametrize("pose", [(20.0, 19.6, 0.3), (14.6, 22.0, 2.0), (24.4, 24.0, -1.0)])
def test_a_scan_is_found_in_the_whole_map_with_no_guess(pose: tuple[float, float, float]) -> None:
    """The thesis labyrinth (40 m x 40 m grid), every position and heading searched."""
    world = thesis_world(ThesisWorld(generator="thesis", experiment=4))
    pyramid = LikelihoodPyramid.from_occupancy(world_cells(world), world.spec, 0.1, 7)
    points = _scan_points(world, pose, np.random.default_rng(7))
    found = best_match(points, pyramid, SearchWindow.covering(world.spec, points))
    assert found is not None
    # Within two cells and two angle steps: the grid's resolution plus the scan's noise.
    assert np.linalg.norm(found.pose[:2] - pose[:2]) <= 2 * world.spec.resolution_m
    assert abs(wrap_angle(found.pose[2] - pose[2])) <= 2 * found.angle_step_rad
