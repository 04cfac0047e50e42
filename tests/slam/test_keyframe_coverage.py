"""Keyframe spacing in mapped space: the coverage test against a brute-force search, and
the spacing a robot gets on a second pass, of its own or of a teammate's path."""

from __future__ import annotations

import numpy as np

from acslam.config import SlamConfig
from acslam.messages import OdometryIncrement
from acslam.slam.backend import SlamBackend
from acslam.slam.keyframe_coverage import KeyframeCoverage

STEP_M = 0.125  # exact in binary, so path sums hit the keyframe thresholds exactly


def test_coverage_matches_a_brute_force_search() -> None:
    rng = np.random.default_rng(3)
    radius_m, min_path_m = 0.5, 5.0
    coverage = KeyframeCoverage(radius_m, min_path_m)
    keyframes = np.column_stack(
        [rng.uniform(-4, 4, (400, 2)), rng.integers(0, 3, 400), rng.uniform(0, 50, 400)]
    )
    for x, y, robot, path in keyframes:
        coverage.add(int(robot), x, y, path)
    queries = np.column_stack(
        [rng.uniform(-5, 5, (2000, 2)), rng.integers(0, 3, 2000), rng.uniform(0, 60, 2000)]
    )
    expected = [
        bool(
            np.any(
                (np.hypot(keyframes[:, 0] - x, keyframes[:, 1] - y) <= radius_m)
                & ((keyframes[:, 2] != robot) | (keyframes[:, 3] <= path - min_path_m))
            )
        )
        for x, y, robot, path in queries
    ]
    found = [coverage.covers(int(r), x, y, p) for x, y, r, p in queries]
    assert found == expected
    assert 0.2 < np.mean(expected) < 0.8  # both answers are exercised


def _drive(backend: SlamBackend, robot: int, steps: int, turn_at: int | None = None) -> None:
    """``steps`` noiseless steps of STEP_M straight on; at step ``turn_at`` a half turn on
    the spot, as one increment (it opens a keyframe by the angle rule)."""
    for k in range(1, steps + 1):
        dtheta = np.pi if k == turn_at else 0.0
        dx = 0.0 if k == turn_at else STEP_M
        stamp = 100.0 * robot + 0.1 * k
        backend.add_odometry(OdometryIncrement(robot, stamp, stamp - 0.1, dx, 0.0, dtheta))


def _keyframe_xs(backend: SlamBackend, robot: int) -> np.ndarray:
    return backend.trajectory(robot)[1][:, 0]


def test_a_teammates_second_pass_opens_keyframes_at_the_mapped_spacing() -> None:
    """Robot 1 drives 3 m of new space, then robot 0's 20 m line 0.2 m beside it, then
    on into new space: a keyframe every 0.375 m (3 steps) until robot 0's keyframes are
    within 0.5 m, every 1.5 m (12 steps) along them, every 0.375 m again beyond them.
    With the option off, robot 1 keeps the dense spacing throughout."""
    starts = {0: np.zeros(3), 1: np.array([-3.0, 0.2, 0.0])}
    backend = SlamBackend(SlamConfig(), starts)
    _drive(backend, 0, 160)
    _drive(backend, 1, 200)
    assert np.allclose(np.diff(_keyframe_xs(backend, 0)), 0.375)
    xs = _keyframe_xs(backend, 1)
    gaps = np.diff(xs)
    # At -0.75 m robot 0's start is 0.78 m away, at -0.375 m 0.43 m: covered from there.
    # Robot 0's last keyframe is at 19.875 m; at 20.625 m robot 1 is 0.78 m from it.
    before, along, after = xs[1:] <= -0.75, (xs[:-1] >= -0.75) & (xs[1:] <= 20.25), xs[:-1] >= 20.25
    assert np.allclose(gaps[before], 0.375) and np.count_nonzero(before) == 6
    assert np.allclose(gaps[along], 1.5) and np.count_nonzero(along) == 14
    assert np.allclose(gaps[after], 0.375) and np.count_nonzero(after) == 4
    off = SlamBackend(SlamConfig(mapped_keyframe_distance_m=0.0), starts)
    _drive(off, 0, 160)
    _drive(off, 1, 200)
    assert np.allclose(np.diff(_keyframe_xs(off, 1)), 0.375)


def test_a_robot_back_on_its_own_path_counts_it_mapped_from_min_path_on() -> None:
    """Out 10 m, a half turn, back 10 m: on the way back the robot's own keyframes count
    once one within 0.5 m is at least 5 m back along its path, from 2.375 m after the turn
    on; the keyframe after the one at 2.25 m waits for 1.5 m of path."""
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    _drive(backend, 0, 161, turn_at=81)
    xs = _keyframe_xs(backend, 0)
    back = xs[int(np.argmax(xs)) :]
    gaps = -np.diff(back)
    near_turn = back[:-1] > 10.0 - 2.25 + 1e-9
    assert np.allclose(gaps[near_turn], 0.375) and np.count_nonzero(near_turn) == 6
    assert np.allclose(gaps[~near_turn], 1.5) and np.count_nonzero(~near_turn) == 5
