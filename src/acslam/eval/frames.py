"""Scoring a run with unknown relative starts (:mod:`acslam.pipeline.frames`).

Each frame's origin is its first robot's start, which the server never knew. The scorer
knows it (the simulator's truth), so it places every frame in the world to score maps
and trajectories as in any run, and judges each merge: the pose found for the merged
frame against the true one. A merge more than ``FALSE_MERGE_M`` or ``FALSE_MERGE_RAD``
off is a false merge.

That judgement also charges a merge with the drift of both frames: a frame whose heading
drifted 0.015 rad puts a place 45 m from its origin 0.7 m off, and a merge that lays the
other frame's map exactly onto that frame's map there is 0.7 m off too. So each merge is
also judged locally, against where each frame's own keyframes near the merged robots
place the truth (``local_error_m``, ``false_locally``): a merge onto the wrong place
fails both, a merge of drifted frames fails only the first.

A merge needs the robots to see each other (:func:`acslam.pipeline.frames.sighting`), so
each merge also says when the two frames' robots first stood within a LiDAR's reach of
each other with nothing between them (``met_s``): a merge long after that was missed
where it could have been made; one soon after it was as early as the robots' meeting.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from acslam.eval.metrics import interpolate_poses
from acslam.eval.slam_figures import plot_map_panels
from acslam.geometry import (
    between,
    between_rows,
    compose,
    transform_points,
    wrap_angle,
    wrap_angles,
)
from acslam.grid import OCCUPIED, UNKNOWN, GridSpec
from acslam.mapping.merge import overlay, place_grid
from acslam.pipeline.frames import FrameMerge, frame_name
from acslam.pipeline.snapshot import Snapshot
from acslam.worlds.starts import line_of_sight
from acslam.worlds.world import World

FALSE_MERGE_M = 0.3
FALSE_MERGE_RAD = math.radians(5.0)
LOCAL_RADIUS_M = 8.0
"""Both frames' keyframes within this of the merged robots (as the merge placed them)
tell how each frame lies on the truth there: the simulated LiDAR's reach, so the maps the
merge matched (at 5 m, office_d seed 0's first merge, at 48 s, had too few)."""
LOCAL_MIN_KEYFRAMES = 5


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


def world_values(
    snapshot: Snapshot,
    true_starts: np.ndarray,
    spec: GridSpec,
    motion: np.ndarray | None = None,
) -> np.ndarray:
    """The team's map on the world's grid: every frame's map placed and overlaid; moved
    on its way by the rigid ``motion`` ``[x, y, theta]`` if given (the team's alignment
    onto the truth)."""
    if not snapshot.frames:
        values = snapshot.map.occupancy_values()
        return values if motion is None else _placed_for_scoring(values, spec, motion, spec)
    values = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    for view in snapshot.frames:
        origin = true_starts[view.robot_ids[0]]
        if motion is not None:
            origin = compose(motion, origin)
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
        marked = np.where(mask, np.int8(1), np.int8(UNKNOWN))  # place_grid reads only known cells
        known |= place_grid(marked, view.spec, origin, spec) == 1
    return known


def pose_error(estimated: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    """Position (m) and wrapped heading (rad) error of a pose."""
    return (
        float(np.hypot(*(np.asarray(estimated[:2]) - true[:2]))),
        abs(wrap_angle(float(estimated[2] - true[2]))),
    )


JUDGEMENT_KEYS = (
    "true_pose_in_frame", "error_m", "error_rad", "error_at_robots_m", "false", "false_at_robots",
    "local_error_m", "local_error_rad", "false_locally",
)  # fmt: skip
"""What a merge's entry says of it against the truth."""


def merge_metrics(
    snapshot: Snapshot,
    true_starts: np.ndarray,
    truth: list[np.ndarray],
    names: list[str],
    world: World | None = None,
    sighting_reach_m: float = 0.0,
) -> dict:
    """Every merge judged against the truth, and per robot when its frame joined robot 0's
    and how far its estimated start in that frame is from the truth.

    A merge's ``error_m`` is at the merged frame's origin, the start of a robot that then
    drifted alone before the maps met (a heading drift of 0.02 rad moves a start 10 m
    away by 0.2 m); ``error_at_robots_m`` is where the merge put the merged robots
    against where they truly stood then (``truth``: ``[t, x, y, theta]`` rows per
    robot), which a merge of the wrong places gets wrong by metres.

    ``local_error_m`` and ``local_error_rad`` are what the merge itself got wrong, without
    either frame's drift: where it put the merged frame's keyframes within
    ``LOCAL_RADIUS_M`` of the merged robots against where the joined frame's own
    keyframes there place them (:func:`_local_error`). None where either frame has fewer
    than ``LOCAL_MIN_KEYFRAMES`` keyframes there; ``false_merges_locally`` counts only the
    merges judged so.

    ``met_s``: when a robot of one of the merge's frames and one of the other first stood
    within ``sighting_reach_m`` of each other with nothing of ``world`` between them (by
    the truth): the first chance of a sighting. None without the world, or if they never
    did before the merge.

    A robot without truth rows (a real one) has no true start either: a merge of its
    frame, or into it, is listed with its judgement None, as is ``false_merges`` when
    any merge is not judged."""
    has_truth = [len(trajectory) > 0 for trajectory in truth]
    merges = []
    for merge in snapshot.merges:
        into, merged = merge.into_robot_ids[0], merge.merged_robot_ids[0]
        assert merge.decision.pose is not None
        met_s = None
        if all(has_truth[r] for r in (into, *merge.merged_robot_ids)):
            judgement = _judged(merge, true_starts, truth)
            if world is not None:
                met_s = _first_met_s(
                    world, sighting_reach_m, truth, merge.into_robot_ids,
                    merge.merged_robot_ids, merge.time_s,
                )  # fmt: skip
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
                "met_s": met_s,
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
        "false_merges_locally": sum(bool(m["false_locally"]) for m in merges) if judged else None,
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
    stood = _true_poses(truth, merge.merged_robot_ids, merge.poses_time_s)[:, :2]
    stood_in_frame = transform_points(between(true_starts[into], np.zeros(3)), stood)
    at_robots_m = float(np.max(np.hypot(*(placed - stood_in_frame).T)))
    local = _local_error(merge, true_starts, truth)
    return {
        "true_pose_in_frame": [float(v) for v in true],
        "error_m": error_m,
        "error_rad": error_rad,
        "error_at_robots_m": at_robots_m,
        "false": error_m > FALSE_MERGE_M or error_rad > FALSE_MERGE_RAD,
        "false_at_robots": at_robots_m > FALSE_MERGE_M or error_rad > FALSE_MERGE_RAD,
        "local_error_m": None if local is None else local[0],
        "local_error_rad": None if local is None else local[1],
        "false_locally": None
        if local is None
        else local[0] > FALSE_MERGE_M or local[1] > FALSE_MERGE_RAD,
    }


def _local_error(
    merge: FrameMerge, true_starts: np.ndarray, truth: list[np.ndarray]
) -> tuple[float, float] | None:
    """The merge's error where it was made, in m and rad (see :func:`merge_metrics`), or
    None where either frame has too few keyframes there.

    Both frames' keyframes near the merged robots are put in the joined frame, by their
    estimates (the merged frame's through the merge) and by the truth. The joined frame's
    keyframes give how that frame lies on the truth there; through it, the truth says
    where the joined frame's map has the merged frame's keyframes, and the motion from
    there to where the merge put them is the merge's own error."""
    origin = true_starts[merge.into_robot_ids[0]]
    placed_xy = placed_poses(merge.decision.pose, merge.merged_poses)[:, :2]
    into_estimated, into_true = _keyframes_near(
        merge.into_robot_ids, merge.into_trajectories, np.zeros(3), origin, truth, placed_xy
    )
    merged_estimated, merged_true = _keyframes_near(
        merge.merged_robot_ids, merge.merged_trajectories, merge.decision.pose, origin, truth,
        placed_xy,
    )  # fmt: skip
    if min(len(into_true), len(merged_true)) < LOCAL_MIN_KEYFRAMES:
        return None
    drift = _motion_between(into_true, into_estimated)
    expected = placed_poses(drift, merged_true)
    error = _motion_between(expected, merged_estimated)
    gaps_m = np.linalg.norm(transform_points(error, placed_xy) - placed_xy, axis=1)
    return float(np.max(gaps_m)), abs(float(error[2]))


def _keyframes_near(
    robot_ids: tuple[int, ...],
    trajectories: tuple[tuple[np.ndarray, np.ndarray], ...],
    frame_pose: np.ndarray,
    origin: np.ndarray,
    truth: list[np.ndarray],
    centres_xy: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The keyframes of a frame (at ``frame_pose`` in the joined frame) whose estimates
    lie within ``LOCAL_RADIUS_M`` of ``centres_xy`` there: (N, 3) estimated and true
    poses in the joined frame (whose first robot truly started at ``origin``)."""
    estimated, true = [], []
    for robot_id, (stamps, poses) in zip(robot_ids, trajectories, strict=True):
        rows = truth[robot_id]
        world = interpolate_poses(np.asarray(stamps, float), rows[:, 0], rows[:, 1:4])
        placed = placed_poses(frame_pose, poses)
        distance_m = np.linalg.norm(placed[:, None, :2] - centres_xy[None], axis=2).min(axis=1)
        near = (distance_m <= LOCAL_RADIUS_M) & ~np.isnan(world).any(axis=1)
        estimated.append(placed[near])
        true.append(between_rows(np.broadcast_to(origin, world[near].shape), world[near]))
    return np.vstack(estimated), np.vstack(true)


def _motion_between(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rigid motion that lays (N, 3) poses ``source`` onto ``target``: its turn their
    mean heading gap (positions alone leave it open where a robot turned on the spot),
    then the mean shift."""
    gaps_rad = target[:, 2] - source[:, 2]
    turn_rad = math.atan2(float(np.mean(np.sin(gaps_rad))), float(np.mean(np.cos(gaps_rad))))
    turned = transform_points(np.array([0.0, 0.0, turn_rad]), source[:, :2])
    return np.array([*np.mean(target[:, :2] - turned, axis=0), turn_rad])


def _true_poses(truth: list[np.ndarray], robot_ids: tuple[int, ...], time_s: float) -> np.ndarray:
    """(N, 3) where the truth's ``[t, x, y, theta]`` rows put each robot at ``time_s``."""
    when = np.array([time_s])
    return np.vstack([interpolate_poses(when, truth[r][:, 0], truth[r][:, 1:4]) for r in robot_ids])


def _first_met_s(
    world: World,
    reach_m: float,
    truth: list[np.ndarray],
    group_a: tuple[int, ...],
    group_b: tuple[int, ...],
    until_s: float,
) -> float | None:
    """The first truth stamp up to ``until_s`` at which a robot of ``group_a`` and one of
    ``group_b`` stood within ``reach_m`` of each other in line of sight (see
    :func:`merge_metrics`); None if none did."""
    first = None
    for a in group_a:
        rows = truth[a][truth[a][:, 0] <= until_s]
        for b in group_b:
            others = interpolate_poses(rows[:, 0], truth[b][:, 0], truth[b][:, 1:4])
            near = np.hypot(*(others[:, :2] - rows[:, 1:3]).T) < reach_m
            for k in np.flatnonzero(near):
                if first is not None and rows[k, 0] >= first:
                    break
                if line_of_sight(world, rows[k, 1:3], others[k, :2]):
                    first = float(rows[k, 0])
                    break
    return first


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
