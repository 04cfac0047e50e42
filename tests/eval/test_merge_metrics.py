"""Merges judged against the truth, and listed unjudged where a robot has none."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from acslam.eval.frames import JUDGEMENT_KEYS, merge_metrics
from acslam.geometry import between, compose, compose_rows
from acslam.grid import GridSpec
from acslam.mapping.merge import MergeDecision
from acslam.pipeline.frames import FrameMerge
from acslam.worlds.world import World

TRUE_STARTS = np.array([[1.0, 2.0, 0.0], [5.0, 2.0, math.pi / 2]])
"""Robot 1's frame lies 4 m along robot 0's x axis, turned a quarter."""


def _still(x: float, y: float, theta: float) -> np.ndarray:
    """Truth rows of a robot standing at one pose from 0 to 20 s."""
    return np.array([[0.0, x, y, theta], [20.0, x, y, theta]])


def _team(
    merge_pose: np.ndarray,
    merged_pose: np.ndarray,
    into_trajectory: tuple[np.ndarray, np.ndarray],
    time_s: float = 10.0,
) -> SimpleNamespace:
    """What :func:`merge_metrics` reads of a team whose frames merged at ``time_s``:
    robot 1's frame found at ``merge_pose`` in robot 0's, with robot 1 at ``merged_pose``
    in its own frame then (and keyframed there six times before), and robot 0's keyframes
    as its frame had them."""
    decision = MergeDecision(True, "", merge_pose, 0.8, 0.1, 120, 150, 0.0, 0.01, 0.05)
    merged_trajectory = (np.linspace(0.0, time_s, 6), np.tile(merged_pose, (6, 1)))
    merge = FrameMerge(
        time_s, (0,), (1,), decision, merged_pose[None], time_s, (), (), (into_trajectory,),
        (merged_trajectory,),
    )  # fmt: skip
    trajectory = {0: into_trajectory[1][:1], 1: merge_pose[None]}
    localization = SimpleNamespace(trajectory=lambda i: (np.zeros(1), trajectory[i]))
    home = SimpleNamespace(
        name="robot_0/map", robot_ids=(0, 1), snapshot=SimpleNamespace(localization=localization)
    )
    return SimpleNamespace(merges=(merge,), frames=(home,))


def _merged_team() -> SimpleNamespace:
    """Frames merged at 10 s, 0.1 m off along x, with robot 1 standing 1 m along its own
    frame's x axis then; robot 0 keyframed where it stands, (0, 0) of its frame."""
    stamps = np.linspace(0.0, 10.0, 6)
    return _team(
        np.array([4.1, 0.0, math.pi / 2]), np.array([1.0, 0.0, 0.0]), (stamps, np.zeros((6, 3)))
    )


def test_a_merge_is_judged_at_the_merged_frames_origin_and_at_its_robots() -> None:
    # Robot 1 truly stood 1 m along its frame's x axis: (5, 3) in the world.
    truth = [_still(1.0, 2.0, 0.0), _still(5.0, 3.0, math.pi / 2)]
    metrics = merge_metrics(_merged_team(), TRUE_STARTS, truth, ["robot_0", "robot_1"])
    (merge,) = metrics["merges"]
    np.testing.assert_allclose(merge["true_pose_in_frame"], [4.0, 0.0, math.pi / 2])
    assert merge["error_m"] == pytest.approx(0.1) and merge["error_rad"] == pytest.approx(0.0)
    assert merge["error_at_robots_m"] == pytest.approx(0.1)  # the whole frame is 0.1 m off
    assert metrics["false_merges"] == 0 and not merge["false"]
    assert metrics["robots"]["robot_1"]["start_error_m"] == pytest.approx(0.1)
    # Both frames' keyframes lie where their frames have them, near robot 1 as placed:
    # the merge's own error is the same 0.1 m.
    assert merge["local_error_m"] == pytest.approx(0.1)
    assert merge["local_error_rad"] == pytest.approx(0.0, abs=1e-12)
    assert metrics["false_merges_locally"] == 0


DRIFT_RAD = 0.02
"""Robot 0's frame turned this much about its origin: 0.8 m off at 40 m."""


def _drifted_corridor_team(
    offset_m: float, turning: bool = False, merged_drift_rad: float = 0.0
) -> tuple[SimpleNamespace, list[np.ndarray]]:
    """Robot 0 drives 40 m along x from its start in 40 s, keyframing every 0.5 m, and
    its frame's estimates turn ``DRIFT_RAD`` about its origin. Robot 1 (frame origin at
    its true start) stands 1 m beside robot 0's last keyframe, and the merge lays it where
    robot 0's drifted map has that place, ``offset_m`` further along the corridor; its own
    frame turned ``merged_drift_rad`` about its origin. ``turning``: robot 0 instead
    keyframes only at the far end, turning on the spot."""
    stamps = np.arange(81) * 0.5
    start0, start1 = TRUE_STARTS
    world0 = np.column_stack([start0[0] + stamps, np.full(81, start0[1]), np.zeros(81)])
    if turning:
        world0 = np.column_stack([np.full(81, start0[0] + 40.0), world0[:, 1], 0.3 * stamps])
    in_frame0 = np.array([between(start0, p) for p in world0])
    estimated0 = compose_rows(np.array([0.0, 0.0, DRIFT_RAD]), in_frame0)
    stood1 = np.array([start0[0] + 40.0, start0[1] + 1.0, 0.0])
    merged_pose = compose(np.array([0.0, 0.0, merged_drift_rad]), between(start1, stood1))
    placed = compose(np.array([0.0, 0.0, DRIFT_RAD]), between(start0, stood1))
    placed = compose(placed, np.array([offset_m, 0.0, 0.0]))
    merge_pose = compose(placed, between(merged_pose, np.zeros(3)))
    truth = [np.column_stack([stamps, world0]), np.column_stack([[0.0, 40.0], [stood1, stood1]])]
    return _team(merge_pose, merged_pose, (stamps, estimated0), time_s=40.0), truth


def test_a_merge_into_a_drifted_frame_is_judged_where_it_was_made() -> None:
    """A merge onto the right place of a drifted frame is off at the frame's origin by
    the frame's own drift, not where it was made; one onto the wrong place is off both."""
    names = ["robot_0", "robot_1"]
    team, truth = _drifted_corridor_team(offset_m=0.0)
    (merge,) = merge_metrics(team, TRUE_STARTS, truth, names)["merges"]
    assert merge["error_rad"] == pytest.approx(DRIFT_RAD)
    # The drift moves robot 1 (40 m out, 1 m aside) by 0.02 rad x its 40.01 m from the origin.
    assert merge["error_at_robots_m"] == pytest.approx(DRIFT_RAD * math.hypot(40.0, 1.0), 1e-3)
    assert merge["error_at_robots_m"] > 0.3 and merge["false_at_robots"]
    assert merge["local_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert merge["local_error_rad"] == pytest.approx(0.0, abs=1e-9)
    assert merge["false_locally"] is False

    # The merged frame drifted too (robot 1's own pose in it is 0.03 rad off): the merge
    # that lays its map onto robot 0's there is still right where it was made.
    team, truth = _drifted_corridor_team(offset_m=0.0, merged_drift_rad=0.03)
    (merge,) = merge_metrics(team, TRUE_STARTS, truth, names)["merges"]
    assert merge["local_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert merge["local_error_rad"] == pytest.approx(0.0, abs=1e-9)

    team, truth = _drifted_corridor_team(offset_m=1.0)
    metrics = merge_metrics(team, TRUE_STARTS, truth, names)
    (merge,) = metrics["merges"]
    assert merge["local_error_m"] == pytest.approx(1.0, abs=1e-9)
    assert merge["false_locally"] is True and metrics["false_merges_locally"] == 1


def test_the_joined_frames_turn_is_found_from_keyframes_at_one_spot() -> None:
    """Keyframes of a robot turning on the spot lie at one point: their headings, not
    their positions, say how the frame is turned there."""
    team, truth = _drifted_corridor_team(offset_m=0.0, turning=True)
    (merge,) = merge_metrics(team, TRUE_STARTS, truth, ["robot_0", "robot_1"])["merges"]
    assert merge["error_at_robots_m"] > 0.3
    assert merge["local_error_m"] == pytest.approx(0.0, abs=1e-9)
    assert merge["local_error_rad"] == pytest.approx(0.0, abs=1e-9)


def test_a_merge_far_from_the_joined_frames_keyframes_is_not_judged_locally() -> None:
    """Robot 0 keyframed only at its start, 10 m from robot 1: nothing tells how its
    frame lies on the truth there."""
    stamps = np.linspace(0.0, 10.0, 6)
    team = _team(
        np.array([4.1, 0.0, math.pi / 2]), np.array([9.0, 0.0, 0.0]), (stamps, np.zeros((6, 3)))
    )
    truth = [_still(1.0, 2.0, 0.0), _still(5.0, 11.0, math.pi / 2)]
    (merge,) = merge_metrics(team, TRUE_STARTS, truth, ["robot_0", "robot_1"])["merges"]
    assert merge["error_m"] == pytest.approx(0.1)
    assert merge["local_error_m"] is None and merge["false_locally"] is None


def test_a_team_without_ground_truth_gets_its_merges_listed_but_not_judged() -> None:
    """A real team publishes no truth: its scenario's start poses are no truth either."""
    no_truth = [np.zeros((0, 4)), np.zeros((0, 4))]
    metrics = merge_metrics(_merged_team(), TRUE_STARTS, no_truth, ["robot_0", "robot_1"])
    (merge,) = metrics["merges"]
    assert all(merge[key] is None for key in JUDGEMENT_KEYS)
    assert merge["pose_in_frame"] == [4.1, 0.0, math.pi / 2] and merge["time_s"] == 10.0
    assert metrics["false_merges"] is None and metrics["false_merges_at_robots"] is None
    assert metrics["false_merges_locally"] is None
    assert metrics["robots"]["robot_1"] == {"merged_s": 10.0} and metrics["all_merged"]


def _wall_world() -> World:
    """10 m x 4 m, 0.05 m cells, and a wall at x = 5.00-5.05 m from y = 0 up to 2 m."""
    spec = GridSpec(0.0, 0.0, 0.05, 80, 200)
    occupied = np.zeros(spec.shape, dtype=bool)
    occupied[:40, 100] = True
    return World("wall", spec, occupied)


def test_a_merge_says_when_its_robots_first_stood_in_sight_of_each_other() -> None:
    """Robot 0 stands at (4, 1), left of the wall; robot 1 walks up x = 6 m from y = 0.5 m
    at 0.1 m/s. The line between them passes the wall's face x = 5 m at the mean of their
    heights, (1 + y) / 2, so it clears the wall's top (2 m) once y >= 3 m: at 25 s. The
    truth is sampled at 0.5 s past each second, so the first stamp in sight is 25.5 s."""
    stamps = np.arange(60) + 0.5
    robot_0 = np.column_stack([stamps, np.full(60, 4.0), np.full(60, 1.0), np.zeros(60)])
    robot_1 = np.column_stack([stamps, np.full(60, 6.0), 0.5 + 0.1 * stamps, np.zeros(60)])
    truth = [robot_0, robot_1]
    names = ["robot_0", "robot_1"]

    def met_s(time_s: float, reach_m: float) -> float | None:
        team = _team(
            np.array([4.1, 0.0, math.pi / 2]), np.array([1.0, 0.0, 0.0]),
            (np.linspace(0.0, time_s, 6), np.zeros((6, 3))), time_s=time_s,
        )  # fmt: skip
        (merge,) = merge_metrics(team, TRUE_STARTS, truth, names, _wall_world(), reach_m)["merges"]
        return merge["met_s"]

    assert met_s(50.0, 7.8) == pytest.approx(25.5)
    # At 25.5 s they stand hypot(2, 2.05) = 2.86 m apart, and only further after.
    assert met_s(50.0, 2.8) is None
    assert met_s(25.0, 7.8) is None  # merged before they met: seen some other way
    # Without a world nothing says when they met.
    assert merge_metrics(_merged_team(), TRUE_STARTS, truth, names)["merges"][0]["met_s"] is None
