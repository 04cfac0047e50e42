"""Replay UTIAS MRCLAM through the localizer stage and score it against the dataset's
ground truth (:mod:`acslam.eval.metrics`).

Start poses come from each robot's first ground-truth sample only (or from nowhere, with
``unknown_starts``: :mod:`acslam.replay.framed`); after that the
localizer sees odometry and landmark range/bearing points, never identities (unless
``known_association`` is set, the reference mode whose frames carry the barcodes), and
range/bearing sightings of one robot by another (:class:`RobotSighting`), whose robot
barcodes do identify the robot seen. Estimates scored are the final optimised keyframe
trajectories (a smoother's output), against ground truth interpolated to the keyframe
stamps, leaving out gaps of the ground truth longer than ``MAX_GROUNDTRUTH_GAP_S``; dead
reckoning from the same odometry is scored at the same stamps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

from acslam.config import AlgorithmsConfig, SlamConfig
from acslam.datasets.mrclam import ROBOT_IDS, MrclamData, read_mrclam
from acslam.eval.frames import FALSE_MERGE_M, FALSE_MERGE_RAD, placed_poses, pose_error
from acslam.eval.metrics import (
    interpolate_poses,
    localization_errors,
    pairwise_precision_recall,
    pooled_localization_errors,
    team_alignment,
)
from acslam.eval.slam_figures import plot_slam_run, plot_track_panels
from acslam.geometry import (
    between,
    compose,
    fit_rigid,
    transform_points,
    wrap_angles,
)
from acslam.messages import (
    LandmarkObservations,
    OdometryIncrement,
    RobotMessage,
    RobotSighting,
)
from acslam.pipeline.stages import AssociationResult
from acslam.provenance import write_metrics
from acslam.replay import localize, preset
from acslam.replay.framed import FramedReplay, Merge, localize_in_frames
from acslam.slam.factors import radial_variance_m2
from acslam.trajectory import write_tum

MAX_GROUNDTRUTH_GAP_S = 0.25


def geometric_association_ceiling(data: MrclamData, config: SlamConfig) -> dict[str, float]:
    """How well geometry alone could associate, given what no estimator has: the true
    poses (Vicon, interpolated) and the true landmark map.

    Each frame's points are assigned to the true landmarks jointly (one landmark per
    point, least total squared range and bearing error in the configured sigmas, by the
    Hungarian method). The scores bound what PDA can reach on this recording: where
    landmarks stand closer together than the measurement noise, even this assignment is
    wrong, and an estimator that must also estimate poses and landmarks does no better.
    Scoring only: reads ground truth, never feeds the back end.
    """
    subjects = np.array(sorted(data.landmark_truth))
    landmarks = np.array([data.landmark_truth[int(s)] for s in subjects])
    truth, chosen = [], []
    for n, msg in enumerate(data.messages):
        if not isinstance(msg, LandmarkObservations):
            continue
        gt_t, gt = data.groundtruth[msg.robot_id]
        pose = interpolate_poses(np.array([msg.stamp]), gt_t, gt, MAX_GROUNDTRUTH_GAP_S)[0]
        point_subjects = np.asarray(data.point_subjects[n])
        keep = np.isin(point_subjects, subjects)
        if np.isnan(pose).any() or not keep.any():
            continue
        points = msg.points[keep]
        offsets = landmarks - pose[:2]
        true_range = np.hypot(offsets[:, 0], offsets[:, 1])
        true_bearing = np.arctan2(offsets[:, 1], offsets[:, 0]) - pose[2]
        ranges = np.hypot(points[:, 0], points[:, 1])
        bearings = np.arctan2(points[:, 1], points[:, 0])
        sigma_r = np.sqrt(config.landmark_sigma_m**2 + radial_variance_m2(config, ranges))
        sigma_b = np.hypot(config.landmark_sigma_m / np.maximum(ranges, 0.1),
                           config.landmark_angular_sigma_rad)  # fmt: skip
        cost = ((ranges[:, None] - true_range) / sigma_r[:, None]) ** 2 + (
            wrap_angles(bearings[:, None] - true_bearing) / sigma_b[:, None]
        ) ** 2
        rows, cols = linear_sum_assignment(cost)
        truth.append(point_subjects[keep][rows])
        chosen.append(subjects[cols])
    truth_arr, chosen_arr = np.concatenate(truth), np.concatenate(chosen)
    precision, recall = pairwise_precision_recall(truth_arr, chosen_arr)
    return {
        "points": len(truth_arr),
        "point_accuracy": float(np.mean(truth_arr == chosen_arr)),
        "pairwise_precision": precision,
        "pairwise_recall": recall,
    }


def _true_starts(data: MrclamData) -> dict[int, np.ndarray]:
    """Each robot's first ground-truth sample, the start a run with known starts gets."""
    return {r: poses[0] for r, (_, poses) in data.groundtruth.items()}


def _dead_reckoning(data: MrclamData, starts: dict[int, np.ndarray]) -> dict[int, tuple]:
    tracks: dict[int, tuple[list[float], list[np.ndarray]]] = {
        r: ([], [start]) for r, start in starts.items()
    }
    for msg in data.messages:
        if isinstance(msg, LandmarkObservations):
            continue
        stamps, poses = tracks[msg.robot_id]
        if not stamps:
            stamps.append(msg.start_stamp)
        stamps.append(msg.stamp)
        poses.append(compose(poses[-1], msg.delta))
    out = {}
    for robot, (stamps, poses) in tracks.items():
        table = np.array(poses[: len(stamps)])
        table[:, 2] = np.unwrap(table[:, 2])
        out[robot] = (np.array(stamps), table)
    return out


def mrclam_messages(
    data: MrclamData, known_association: bool, inter_robot: bool
) -> list[RobotMessage]:
    """The team's messages in the reader's time order; landmark frames carry their
    barcodes only with ``known_association``; robot sightings follow the messages of their
    stamp (after the odometry up to their time, as the reader orders)."""
    messages: list[RobotMessage] = [
        replace(msg, ids=np.asarray(data.point_subjects[n], dtype=np.int64))
        if known_association and isinstance(msg, LandmarkObservations)
        else msg
        for n, msg in enumerate(data.messages)
    ]
    if inter_robot:
        for t, observer, observed, rng, bearing in data.robot_measurements:
            point = np.array([rng * math.cos(bearing), rng * math.sin(bearing), 0.0])
            messages.append(RobotSighting(int(observer), float(t), int(observed), point))
    return sorted(messages, key=lambda m: m.stamp)


@dataclass
class _Labels:
    """Per associated point, its true subject and the landmark it went to; counts of the
    points that made no factor."""

    truth: np.ndarray
    estimated: np.ndarray
    dropped: int
    tentative: int


def _association_labels(
    landmark_frames: list[tuple[LandmarkObservations, list[AssociationResult]]], data: MrclamData
) -> _Labels:
    subjects_of = {id(data.messages[n]): subjects for n, subjects in data.point_subjects.items()}
    truth, estimated, dropped, tentative = [], [], 0, 0
    for frame, results in landmark_frames:
        subjects = subjects_of.get(id(frame))
        if subjects is None:  # a frame that carries its barcodes
            subjects = frame.ids
        for subject, result in zip(subjects, results, strict=True):
            if result.tentative:
                tentative += 1
            elif result.landmark < 0:
                dropped += 1
            else:
                truth.append(int(subject))
                estimated.append(result.landmark)
    return _Labels(np.array(truth), np.array(estimated), dropped, tentative)


def _landmark_errors(landmarks: np.ndarray, labels: _Labels, data: MrclamData) -> dict:
    """Per true landmark, the distance to the estimate most of its points went to."""
    errors = {}
    for subject, position in sorted(data.landmark_truth.items()):
        mine = labels.estimated[labels.truth == subject]
        if len(mine):
            best = int(np.bincount(mine).argmax())
            errors[str(subject)] = float(np.linalg.norm(landmarks[best, :2] - position))
    return errors


@dataclass
class _Scores:
    """Per robot: errors of SLAM and dead reckoning, the runs they pooled from, tracks."""

    per_robot: dict[str, dict] = field(default_factory=dict)
    slam_runs: list[tuple] = field(default_factory=list)
    dr_runs: list[tuple] = field(default_factory=list)
    slam_tracks: dict[int, np.ndarray] = field(default_factory=dict)
    dr_tracks: dict[int, np.ndarray] = field(default_factory=dict)
    truth_tracks: dict[int, np.ndarray] = field(default_factory=dict)


def _score_robots(
    trajectories: dict[int, tuple[np.ndarray, np.ndarray]], data: MrclamData, out_dir: Path
) -> _Scores:
    """Each robot's keyframe trajectory, and dead reckoning from its true start, against
    the ground truth; writes their TUM files."""
    dead_reckoning = _dead_reckoning(data, _true_starts(data))
    scores = _Scores()
    for robot in sorted(trajectories):
        stamps, poses = trajectories[robot]
        poses[:, 2] = np.unwrap(poses[:, 2])
        gt_t, gt = data.groundtruth[robot]
        dr_t, dr = dead_reckoning[robot]
        scores.slam_runs.append((stamps, poses, gt_t, gt))
        scores.dr_runs.append((stamps, interpolate_poses(stamps, dr_t, dr), gt_t, gt))
        slam_err = localization_errors(*scores.slam_runs[-1], MAX_GROUNDTRUTH_GAP_S)
        dr_err = localization_errors(*scores.dr_runs[-1], MAX_GROUNDTRUTH_GAP_S)
        scores.per_robot[str(robot)] = {
            "keyframes": len(stamps),
            "slam": slam_err,
            "dead_reckoning": dr_err,
            "rmse_improvement_factor": dr_err["rmse_m"] / slam_err["rmse_m"],
        }
        scores.slam_tracks[robot], scores.dr_tracks[robot] = poses, dr
        scores.truth_tracks[robot] = gt
        write_tum(out_dir / f"robot{robot}_slam.tum", stamps, poses)
        write_tum(out_dir / f"robot{robot}_dead_reckoning.tum", dr_t, dr)
        write_tum(out_dir / f"robot{robot}_groundtruth.tum", gt_t, gt)
    return scores


def _frame_origins(data: MrclamData, messages: Sequence[RobotMessage]) -> dict[int, np.ndarray]:
    """Each robot's true pose where its own frame starts: at its first odometry."""
    first: dict[int, float] = {}
    for message in messages:
        if isinstance(message, OdometryIncrement):
            first.setdefault(message.robot_id, message.start_stamp)
    return {
        r: interpolate_poses(np.array([stamp]), *data.groundtruth[r])[0]
        for r, stamp in first.items()
    }


def _pose_error(estimate: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    translation_m, rotation_rad = pose_error(estimate, truth)
    return {"translation_m": translation_m, "rotation_rad": rotation_rad}


def _error_at_robots(merge: Merge, data: MrclamData) -> dict[str, float]:
    """How far the merged frame's robots, as its graph placed their latest keyframes at
    the merge, lie from the truth after the one rigid motion that best lays their
    positions on it: the worst robot's position, and the widest spread of their headings
    about the mean.

    A merge is judged false by the position (over ``FALSE_MERGE_M``): a
    frame's origin is a start pose, whose heading only that robot's odometry ties to the
    rest of its path, and one keyframe's heading is no better known (with known starts,
    this recording's heading RMSE is 5.4 degrees, its maximum 36), so neither tells a
    wrong merge from a right one by a 5 degree bound; both are reported."""
    robots = sorted(merge.placed)
    placed = np.array([merge.placed[r][1] for r in robots])
    truth = np.array(
        [interpolate_poses(np.array([merge.placed[r][0]]), *data.groundtruth[r])[0] for r in robots]
    )
    motion = fit_rigid(placed[:, :2], truth[:, :2])
    aligned = transform_points(motion, placed[:, :2])
    headings = wrap_angles(placed[:, 2] + motion[2] - truth[:, 2])
    headings = wrap_angles(headings - np.angle(np.mean(np.exp(1j * headings))))
    return {
        "translation_m": float(np.max(np.hypot(*(aligned - truth[:, :2]).T))),
        "heading_spread_rad": float(np.max(np.abs(headings))),
    }


def _merge_metrics(
    framed: FramedReplay, data: MrclamData, messages: Sequence[RobotMessage]
) -> dict:
    """Per merge: when, what, the fit, and its errors against the truth (see the module
    docstring); the robots left unmerged; false merges by either error."""
    origins = _frame_origins(data, messages)
    first_s = messages[0].stamp
    merges = []
    for merge in framed.merges:
        true_origin = between(origins[merge.into], origins[merge.merged])
        assert merge.alignment.pose_b_in_a is not None
        error_at_robots = _error_at_robots(merge, data)
        merges.append(
            {
                "merged_at_s": merge.stamp - first_s,
                "frame": f"robot {merge.merged}'s",
                "into": f"robot {merge.into}'s",
                "robots": merge.robot_ids,
                "fit": merge.alignment.as_dict(),
                "origin_error_of_fit": _pose_error(merge.alignment.pose_b_in_a, true_origin),
                "origin_error": _pose_error(merge.origin_in_into, true_origin),
                "error_at_robots": error_at_robots,
                "false": error_at_robots["translation_m"] > FALSE_MERGE_M,
            }
        )
    reference = framed.frames[min(framed.frames)]
    return {
        "merges": merges,
        "all_merged": len(framed.frames) == 1,
        "reference_frame": f"robot {reference.base}'s start",
        "unmerged_robots": sorted(r for f in framed.frames.values() if f is not reference
                                  for r in f.starts),
        "false_merges": sum(m["false"] for m in merges),
        "origins_off_by_more_than_the_false_merge_bound": sum(
            m["origin_error"]["translation_m"] > FALSE_MERGE_M
            or m["origin_error"]["rotation_rad"] > FALSE_MERGE_RAD
            for m in merges
        ),
    }  # fmt: skip


def _plot_merges(framed: FramedReplay, out_dir: Path) -> None:
    """``merges/merge_<k>.png`` per merge: both frames before, the merged frame after."""
    for k, merge in enumerate(framed.merges, start=1):
        into, merged = merge.before
        plot_track_panels(
            out_dir / "merges" / f"merge_{k}.png",
            [
                (into.tracks, into.landmarks, f"before: robot {merge.into}'s frame"),
                (merged.tracks, merged.landmarks, f"robot {merge.merged}'s frame"),
                (merge.after.tracks, merge.after.landmarks,
                 f"after: merged at {merge.stamp - framed.start_s:.0f} s"),
            ],
        )  # fmt: skip


def _aligned(
    trajectories: dict[int, tuple[np.ndarray, np.ndarray]], data: MrclamData
) -> tuple[dict[int, tuple[np.ndarray, np.ndarray]], dict, np.ndarray]:
    """The trajectories laid on the truth by the one rigid motion that fits the team
    best (:func:`team_alignment`), that alignment, and the motion."""
    alignment = team_alignment(
        [(*trajectories[r], *data.groundtruth[r]) for r in sorted(trajectories)],
        MAX_GROUNDTRUTH_GAP_S,
    )
    motion = np.array([*alignment["translation_m"], alignment["rotation_rad"]])
    moved = {
        r: (stamps, placed_poses(motion, poses)) for r, (stamps, poses) in trajectories.items()
    }
    return moved, alignment, motion


def run_mrclam(
    path: str | Path,
    out_dir: str | Path,
    *,
    known_association: bool = False,
    max_time_s: float | None = None,
    algorithms: AlgorithmsConfig | None = None,
    inter_robot: bool = True,
    unknown_starts: bool = False,
) -> dict:
    """Run with ``algorithms`` (default: the ``mrclam`` preset), score and write
    DIR/metrics.json, TUM trajectories and DIR/trajectories.png.

    ``inter_robot`` adds a factor for each measurement of one robot by another (the seen
    robot recognised by its own barcode). They come from the same camera as the landmark
    points and are as accurate (range MAD ~5 cm, bearing ~5 mrad against ground truth),
    so they share the landmark sigmas.

    ``unknown_starts``: no start poses; each robot starts in its own frame and the
    frames merge where the sightings place them (:mod:`acslam.replay.framed`). The robots
    of the first robot's frame are scored after the one rigid motion that lays the team
    on the truth (the frame is the first robot's start, not the truth's), and
    ``unknown_starts`` judges every merge. Dead reckoning starts at the true starts.
    """
    algorithms = algorithms or preset("mrclam")
    out_dir = Path(out_dir)
    data = read_mrclam(path, max_time_s)
    messages = mrclam_messages(data, known_association, inter_robot)
    merge_metrics, alignment = None, None
    if unknown_starts:
        if not inter_robot:
            raise ValueError("robots with unknown starts merge by their sightings of each other")
        framed = localize_in_frames(messages, algorithms, ROBOT_IDS)
        reference = framed.frames[min(framed.frames)]
        localizer = reference.perception.localizer
        trajectories, alignment, motion = _aligned(
            {r: localizer.trajectory(r) for r in reference.starts}, data
        )
        landmark_frames = reference.landmarks
        landmarks = localizer.landmarks()
        landmarks[:, :2] = transform_points(motion, landmarks[:, :2])
        merge_metrics = _merge_metrics(framed, data, messages)
        _plot_merges(framed, out_dir)
    else:
        replayed = localize(messages, algorithms, _true_starts(data))
        localizer = replayed.localizer
        trajectories = {r: localizer.trajectory(r) for r in ROBOT_IDS}
        landmark_frames = replayed.landmarks
        landmarks = localizer.landmarks()
    diagnostics = localizer.diagnostics()
    labels = _association_labels(landmark_frames, data)
    scores = _score_robots(trajectories, data, out_dir)
    landmark_errors = _landmark_errors(landmarks, labels, data)
    precision, recall = pairwise_precision_recall(labels.truth, labels.estimated)
    errors = np.array(list(landmark_errors.values()))
    association = diagnostics["landmark_association"]
    metrics = {
        "dataset": str(path),
        "known_association": known_association,
        "inter_robot": inter_robot,
        "max_time_s": max_time_s,
        "robots": scores.per_robot,
        "overall": {
            "slam": pooled_localization_errors(scores.slam_runs, MAX_GROUNDTRUTH_GAP_S),
            "dead_reckoning": pooled_localization_errors(scores.dr_runs, MAX_GROUNDTRUTH_GAP_S),
        },
        "landmarks": {
            "estimated": len(landmarks),
            "observed_true": len(landmark_errors),
            "rmse_m": float(np.sqrt(np.mean(errors**2))) if len(errors) else math.nan,
            "per_subject_error_m": landmark_errors,
        },
        "association": {
            "pairwise_precision": precision,
            "pairwise_recall": recall,
            "points_associated": len(labels.truth),
            "points_dropped_ambiguous": labels.dropped,
            "points_tentative": labels.tentative,
            "landmarks_tentative_expired": association["tentatives_expired"],
            "geometric_ceiling": geometric_association_ceiling(data, algorithms.localizer),
        },
        "isam2_update_ms": diagnostics["isam2_update_ms"],
        "skipped": {**data.skipped, **diagnostics["skipped_messages"]},
        "robot_measurements": {
            "total": len(data.robot_measurements),
            "factors": diagnostics["robot_sightings"],
        },
    }
    if unknown_starts:
        metrics["relative_starts"] = "unknown"
        metrics["scored_after"] = "team_alignment, of the robots of the first robot's frame"
        metrics["team_alignment"] = alignment
        metrics["unknown_starts"] = merge_metrics
    out_dir.mkdir(parents=True, exist_ok=True)
    metrics = write_metrics(out_dir, metrics)
    truth_lm = np.array(list(data.landmark_truth.values()))
    mode = ("known association" if known_association else "PDA") + (
        ", unknown starts, aligned" if unknown_starts else ""
    )
    plot_slam_run(
        out_dir / "trajectories.png",
        scores.truth_tracks,
        scores.slam_tracks,
        scores.dr_tracks,
        truth_lm,
        landmarks,
        f"MRCLAM SLAM ({mode})",
    )
    return metrics
