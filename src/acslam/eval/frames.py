"""Scoring a run with unknown relative starts (:mod:`acslam.pipeline.frames`).

Each frame's origin is its first robot's start, which the server never knew. The scorer
knows it (the simulator's truth), so it places every frame in the world to score maps
and trajectories as in any run, and judges each merge: the pose found for the merged
frame against the true one. A merge more than ``FALSE_MERGE_M`` or ``FALSE_MERGE_RAD``
off is a false merge.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from acslam.eval.slam_figures import plot_map_panels
from acslam.geometry import between, transform_points, wrap_angle, wrap_angles
from acslam.grid import OCCUPIED, UNKNOWN, GridSpec
from acslam.mapping.merge import overlay, place_grid
from acslam.pipeline.frames import FrameMerge, frame_name
from acslam.pipeline.snapshot import Snapshot

FALSE_MERGE_M = 0.3
FALSE_MERGE_RAD = math.radians(5.0)


def frame_origins(snapshot: Snapshot, true_starts: np.ndarray) -> dict[int, np.ndarray]:
    """Per robot, where its frame lies in the world: its frame's first robot's true start."""
    return {
        robot_id: np.asarray(true_starts[view.robot_ids[0]], dtype=float)
        for view in snapshot.frames
        for robot_id in view.robot_ids
    }


def placed_poses(origin: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N, 3) poses of a frame at ``origin``, in the world."""
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    xy = transform_points(origin, poses[:, :2])
    return np.column_stack([xy, wrap_angles(poses[:, 2] + origin[2])])


def world_values(snapshot: Snapshot, true_starts: np.ndarray, spec: GridSpec) -> np.ndarray:
    """The team's map on the world's grid: every frame's map placed and overlaid."""
    if not snapshot.frames:
        return snapshot.map.occupancy_values()
    values = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    for view in snapshot.frames:
        origin = true_starts[view.robot_ids[0]]
        frame_values = view.snapshot.map.occupancy_values()
        values = overlay(values, _placed_for_scoring(frame_values, view.spec, origin, spec))
    return values


def _placed_for_scoring(
    values: np.ndarray, spec: GridSpec, origin: np.ndarray, target: GridSpec
) -> np.ndarray:
    """A frame's map on the world's lattice, its walls kept whole. The frame's cells lie
    between the world's (turned, and up to half a cell off), and the nearest frame cell
    alone shifts a thin wall by a cell along half its length, which scores as walls
    missed. So a world cell is occupied where the frame cell under any quarter of it is
    (read a quarter cell off its centre each way), else it takes the nearest value."""
    placed = place_grid(values, spec, origin, target)
    quarter_m = 0.25 * target.resolution_m
    for dx in (-quarter_m, quarter_m):
        for dy in (-quarter_m, quarter_m):
            shifted = replace(
                target, origin_x_m=target.origin_x_m + dx, origin_y_m=target.origin_y_m + dy
            )
            placed[place_grid(values, spec, origin, shifted) == OCCUPIED] = OCCUPIED
    return placed


def world_known(
    snapshot: Snapshot, true_starts: np.ndarray, spec: GridSpec, robot_id: int | None = None
) -> np.ndarray:
    """Cells of the world's grid the team (or robot ``robot_id``) observed."""
    if not snapshot.frames:
        if robot_id is None:
            return snapshot.map.known_mask()
        return snapshot.map.robot_known_mask(robot_id)
    known = np.zeros(spec.shape, dtype=bool)
    for view in snapshot.frames:
        if robot_id is None:
            mask = view.snapshot.map.known_mask()
        elif robot_id in view.robot_ids:
            mask = view.snapshot.map.robot_known_mask(view.robot_ids.index(robot_id))
        else:
            continue
        origin = true_starts[view.robot_ids[0]]
        known |= place_grid(mask.astype(np.int8), view.spec, origin, spec) == 1
    return known


def pose_error(estimated: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    """Position (m) and wrapped heading (rad) error of a pose."""
    return (
        float(np.hypot(*(np.asarray(estimated[:2]) - true[:2]))),
        abs(wrap_angle(float(estimated[2] - true[2]))),
    )


JUDGEMENT_KEYS = (
    "true_pose_in_frame", "error_m", "error_rad", "error_at_robots_m", "false", "false_at_robots",
)  # fmt: skip
"""What a merge's entry says of it against the truth."""


def merge_metrics(
    snapshot: Snapshot, true_starts: np.ndarray, truth: list[np.ndarray], names: list[str]
) -> dict:
    """Every merge judged against the truth, and per robot when its frame joined robot 0's
    and how far its estimated start in that frame is from the truth.

    A merge's ``error_m`` is at the merged frame's origin, the start of a robot that then
    drifted alone before the maps met (a heading drift of 0.02 rad moves a start 10 m
    away by 0.2 m); ``error_at_robots_m`` is where the merge put the merged robots
    against where they truly stood then (``truth``: ``[t, x, y, theta]`` rows per
    robot), which a merge of the wrong places gets wrong by metres.

    A robot without truth rows (a real one) has no true start either: a merge of its
    frame, or into it, is listed with its judgement None, as is ``false_merges`` when
    any merge is not judged."""
    has_truth = [len(trajectory) > 0 for trajectory in truth]
    merges = []
    for merge in snapshot.merges:
        into, merged = merge.into_robot_ids[0], merge.merged_robot_ids[0]
        assert merge.decision.pose is not None
        if all(has_truth[r] for r in (into, *merge.merged_robot_ids)):
            judgement = _judged(merge, true_starts, truth)
        else:
            judgement = dict.fromkeys(JUDGEMENT_KEYS)
        merges.append(
            {
                "time_s": merge.time_s,
                "into": frame_name(into),
                "merged": frame_name(merged),
                "robots": [names[r] for r in merge.merged_robot_ids],
                "pose_in_frame": [float(v) for v in merge.decision.pose],
                **judgement,
                "matched_points": merge.decision.matched_points,
                "score": merge.decision.score,
                "second_score": merge.decision.second_score,
            }
        )
    robots = {}
    home = next(view for view in snapshot.frames if 0 in view.robot_ids)
    for robot_id, name in enumerate(names):
        robots[name] = {"merged_s": _joined_robot_0_s(snapshot.merges, robot_id)}
        if robot_id in home.robot_ids and has_truth[0] and has_truth[robot_id]:
            _, poses = home.snapshot.localization.trajectory(home.robot_ids.index(robot_id))
            start = poses[0]
            true = between(true_starts[0], true_starts[robot_id])
            error_m, error_rad = pose_error(start, true)
            robots[name].update(start_error_m=error_m, start_error_rad=error_rad)
    judged = all(m["false"] is not None for m in merges)
    return {
        "merges": merges,
        "false_merges": sum(m["false"] for m in merges) if judged else None,
        "false_merges_at_robots": sum(m["false_at_robots"] for m in merges) if judged else None,
        "all_merged": len(snapshot.frames) == 1,
        "frames_at_end": [view.name for view in snapshot.frames],
        "robots": robots,
    }


def _judged(merge: FrameMerge, true_starts: np.ndarray, truth: list[np.ndarray]) -> dict:
    """A merge against the truth: the ``JUDGEMENT_KEYS`` (see :func:`merge_metrics`)."""
    into = merge.into_robot_ids[0]
    assert merge.decision.pose is not None
    true = between(true_starts[into], true_starts[merge.merged_robot_ids[0]])
    error_m, error_rad = pose_error(merge.decision.pose, true)
    placed = transform_points(merge.decision.pose, merge.merged_poses[:, :2])
    stood = np.array(
        [_true_xy(truth[r], merge.poses_time_s) for r in merge.merged_robot_ids]
    ).reshape(-1, 2)
    stood_in_frame = transform_points(between(true_starts[into], np.zeros(3)), stood)
    at_robots_m = float(np.max(np.hypot(*(placed - stood_in_frame).T)))
    return {
        "true_pose_in_frame": [float(v) for v in true],
        "error_m": error_m,
        "error_rad": error_rad,
        "error_at_robots_m": at_robots_m,
        "false": error_m > FALSE_MERGE_M or error_rad > FALSE_MERGE_RAD,
        "false_at_robots": at_robots_m > FALSE_MERGE_M or error_rad > FALSE_MERGE_RAD,
    }


def _true_xy(trajectory: np.ndarray, time_s: float) -> np.ndarray:
    """Where the truth's ``[t, x, y, theta]`` rows put the robot at ``time_s``."""
    return np.array([np.interp(time_s, trajectory[:, 0], trajectory[:, k]) for k in (1, 2)])


def _joined_robot_0_s(merges: tuple[FrameMerge, ...], robot_id: int) -> float | None:
    """When robot ``robot_id`` first shared a frame with robot 0 (robot 0: when its frame
    first took another in); None if never. A merge joins two whole frames."""
    for merge in merges:
        joined = set(merge.into_robot_ids) | set(merge.merged_robot_ids)
        if 0 in joined and robot_id in joined:
            return merge.time_s
    return None


def write_merge_figures(out_dir: Path, merges: tuple[FrameMerge, ...]) -> list[Path]:
    """One figure per merge: the two frames' maps before it and the merged map after."""
    paths = []
    for k, merge in enumerate(merges, start=1):
        into, merged = frame_name(merge.into_robot_ids[0]), frame_name(merge.merged_robot_ids[0])
        path = out_dir / "merges" / f"merge_{k}.png"
        (values_a, spec_a), (values_b, spec_b) = merge.before
        plot_map_panels(
            path,
            [
                (values_a, spec_a, [], f"{into} before (t = {merge.time_s:.1f} s)"),
                (values_b, spec_b, [], f"{merged} before"),
                (*merge.after, [], f"after: {merged} merged into {into}"),
            ],
        )
        paths.append(path)
    return paths
