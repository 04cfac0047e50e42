"""Merges judged against the truth, and listed unjudged where a robot has none."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from acslam.eval.frames import JUDGEMENT_KEYS, merge_metrics
from acslam.mapping.merge import MergeDecision
from acslam.pipeline.frames import FrameMerge

TRUE_STARTS = np.array([[1.0, 2.0, 0.0], [5.0, 2.0, math.pi / 2]])
"""Robot 1's frame lies 4 m along robot 0's x axis, turned a quarter."""


def _merged_team() -> SimpleNamespace:
    """What :func:`merge_metrics` reads of a team whose frames merged at 10 s, 0.1 m off
    along x, with robot 1 standing 1 m along its own frame's x axis then."""
    decision = MergeDecision(
        True, "", np.array([4.1, 0.0, math.pi / 2]), 0.8, 0.1, 120, 150, 0.0, 0.01, 0.05
    )
    merge = FrameMerge(10.0, (0,), (1,), decision, np.array([[1.0, 0.0, 0.0]]), 10.0, (), ())
    trajectory = {0: np.array([[0.0, 0.0, 0.0]]), 1: np.array([[4.1, 0.0, math.pi / 2]])}
    localization = SimpleNamespace(trajectory=lambda i: (np.zeros(1), trajectory[i]))
    home = SimpleNamespace(
        name="robot_0/map", robot_ids=(0, 1), snapshot=SimpleNamespace(localization=localization)
    )
    return SimpleNamespace(merges=(merge,), frames=(home,))


def test_a_merge_is_judged_at_the_merged_frames_origin_and_at_its_robots() -> None:
    # Robot 1 truly stood 1 m along its frame's x axis: (5, 3) in the world.
    truth = [np.array([[0.0, 1.0, 2.0, 0.0]]), np.array([[0.0, 5.0, 3.0, 0.0]])]
    metrics = merge_metrics(_merged_team(), TRUE_STARTS, truth, ["robot_0", "robot_1"])
    (merge,) = metrics["merges"]
    np.testing.assert_allclose(merge["true_pose_in_frame"], [4.0, 0.0, math.pi / 2])
    assert merge["error_m"] == pytest.approx(0.1) and merge["error_rad"] == pytest.approx(0.0)
    assert merge["error_at_robots_m"] == pytest.approx(0.1)  # the whole frame is 0.1 m off
    assert metrics["false_merges"] == 0 and not merge["false"]
    assert metrics["robots"]["robot_1"]["start_error_m"] == pytest.approx(0.1)


def test_a_team_without_ground_truth_gets_its_merges_listed_but_not_judged() -> None:
    """A real team publishes no truth: its scenario's start poses are no truth either."""
    no_truth = [np.zeros((0, 4)), np.zeros((0, 4))]
    metrics = merge_metrics(_merged_team(), TRUE_STARTS, no_truth, ["robot_0", "robot_1"])
    (merge,) = metrics["merges"]
    assert all(merge[key] is None for key in JUDGEMENT_KEYS)
    assert merge["pose_in_frame"] == [4.1, 0.0, math.pi / 2] and merge["time_s"] == 10.0
    assert metrics["false_merges"] is None and metrics["false_merges_at_robots"] is None
    assert metrics["robots"]["robot_1"] == {"merged_s": 10.0} and metrics["all_merged"]
