"""A recording without start poses: two robots that see each other merge into one frame
at the relative start the truth has, and a replay merges the same way every time."""

from __future__ import annotations

import math

import numpy as np

from acslam.geometry import between, compose
from acslam.messages import OdometryIncrement, RobotMessage, RobotSighting
from acslam.replay import preset
from acslam.replay.framed import localize_in_frames

STARTS = {1: np.array([0.0, 0.0, 0.0]), 2: np.array([3.0, 1.0, math.pi / 2])}
SPEEDS = {1: (0.2, 0.1), 2: (0.15, -0.08)}
"""(v m/s, w rad/s) of each robot: two arcs that keep them in sight of each other."""
PERIOD_S = 0.1
DURATION_S = 60.0


def _recording(seed: int) -> list[RobotMessage]:
    """Odometry at 10 Hz with 2 % noise, and each robot's range and bearing to the other
    twice a second with 2 cm / 0.01 rad noise."""
    rng = np.random.default_rng(seed)
    poses = {r: [start] for r, start in STARTS.items()}
    messages: list[RobotMessage] = []
    for step in range(1, int(DURATION_S / PERIOD_S) + 1):
        stamp = 100.0 + step * PERIOD_S
        for robot, (v, w) in SPEEDS.items():
            delta = np.array([v * PERIOD_S, 0.0, w * PERIOD_S])
            poses[robot].append(compose(poses[robot][-1], delta))
            measured = delta * (1 + rng.normal(0, 0.02, 3))
            messages.append(OdometryIncrement(robot, stamp, stamp - PERIOD_S, *measured))
        if step % 5 == 0:
            for observer, seen in ((1, 2), (2, 1)):
                offset = between(poses[observer][-1], poses[seen][-1])
                rng_m = math.hypot(offset[0], offset[1]) + rng.normal(0, 0.02)
                bearing = math.atan2(offset[1], offset[0]) + rng.normal(0, 0.01)
                point = np.array([rng_m * math.cos(bearing), rng_m * math.sin(bearing), 0.0])
                messages.append(RobotSighting(observer, stamp, seen, point))
    return messages


def test_two_robots_merge_at_their_true_relative_start() -> None:
    messages = _recording(seed=1)
    replay = localize_in_frames(messages, preset("mrclam"), [1, 2])
    assert list(replay.frames) == [1]
    (merge,) = replay.merges
    assert (merge.into, merge.merged, merge.robot_ids) == (1, 2, [2])
    true_start = between(STARTS[1], STARTS[2])
    localizer = replay.frames[1].perception.localizer
    start = localizer.trajectory(2)[1][0]
    assert np.hypot(*(start[:2] - true_start[:2])) < 0.1
    assert abs(start[2] - true_start[2]) < math.radians(3)
    _, end = localizer.trajectory(2)
    assert end.shape[0] > 10


def test_same_recording_same_merges() -> None:
    messages = _recording(seed=2)
    first = localize_in_frames(messages, preset("mrclam"), [1, 2])
    second = localize_in_frames(messages, preset("mrclam"), [1, 2])
    assert [m.stamp for m in first.merges] == [m.stamp for m in second.merges]
    for a, b in zip(first.merges, second.merges, strict=True):
        np.testing.assert_array_equal(a.alignment.pose_b_in_a, b.alignment.pose_b_in_a)
        np.testing.assert_array_equal(a.origin_in_into, b.origin_in_into)


def test_robots_that_never_see_each_other_keep_their_frames() -> None:
    messages = [m for m in _recording(seed=3) if not isinstance(m, RobotSighting)]
    replay = localize_in_frames(messages, preset("mrclam"), [1, 2])
    assert sorted(replay.frames) == [1, 2] and not replay.merges
    np.testing.assert_allclose(
        replay.frames[2].perception.localizer.trajectory(2)[1][0], 0.0, atol=1e-9
    )
