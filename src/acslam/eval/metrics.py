"""The thesis's evaluation metrics (chapter 5) as pure functions on arrays.

Nothing here reads files or draws: a run computes the numbers once, and reports are built
from the saved results later.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from itertools import combinations

import numpy as np

from acslam.geometry import fit_rigid, path_length_m, transform_points, wrap_angles
from acslam.grid import OCCUPIED, UNKNOWN


def interpolate_poses(
    stamps: np.ndarray,
    ref_stamps: np.ndarray,
    ref_poses: np.ndarray,
    max_gap_s: float = math.inf,
) -> np.ndarray:
    """Reference poses linearly interpolated at ``stamps`` (heading through its unwrap);
    NaN outside the reference's span or between two samples more than ``max_gap_s``
    apart (a dropout of the reference)."""
    x = np.interp(stamps, ref_stamps, ref_poses[:, 0])
    y = np.interp(stamps, ref_stamps, ref_poses[:, 1])
    theta = wrap_angles(np.interp(stamps, ref_stamps, np.unwrap(ref_poses[:, 2])))
    poses = np.column_stack([x, y, theta])
    right = np.searchsorted(ref_stamps, stamps).clip(1, max(len(ref_stamps) - 1, 1))
    bad = (stamps < ref_stamps[0]) | (stamps > ref_stamps[-1])
    if len(ref_stamps) > 1:
        bad |= (ref_stamps[right] - ref_stamps[right - 1]) > max_gap_s
    poses[bad] = np.nan
    return poses


def _paired_poses(
    stamps: np.ndarray,
    poses: np.ndarray,
    true_stamps: np.ndarray,
    true_poses: np.ndarray,
    max_gap_s: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The estimated poses at the stamps the truth covers, and the truth there."""
    stamps = np.asarray(stamps, dtype=float)
    truth = interpolate_poses(stamps, true_stamps, true_poses, max_gap_s)
    covered = ~np.isnan(truth).any(axis=1)
    return np.asarray(poses, dtype=float)[covered], truth[covered]


def _error_magnitudes(estimate: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position and heading error of each pair of :func:`_paired_poses`."""
    distance = np.hypot(*(estimate[:, :2] - truth[:, :2]).T)
    yaw = np.abs(wrap_angles(estimate[:, 2] - truth[:, 2]))
    return distance, yaw


def _summary(distance: np.ndarray, yaw: np.ndarray) -> dict[str, float]:
    if not len(distance):
        raise ValueError("the estimated trajectory does not overlap the ground truth in time")
    return {
        "final_dist_m": float(distance[-1]),
        "mae_m": float(distance.mean()),
        "rmse_m": float(np.sqrt(np.mean(distance**2))),
        "std_m": float(distance.std()),
        "max_m": float(distance.max()),
        "final_yaw_rad": float(yaw[-1]),
        "mae_yaw_rad": float(yaw.mean()),
        "rmse_yaw_rad": float(np.sqrt(np.mean(yaw**2))),
        "std_yaw_rad": float(yaw.std()),
        "max_yaw_rad": float(yaw.max()),
    }


def localization_errors(
    stamps: np.ndarray,
    poses: np.ndarray,
    true_stamps: np.ndarray,
    true_poses: np.ndarray,
    max_gap_s: float = math.inf,
) -> dict[str, float]:
    """Position and heading errors of a trajectory against ground truth (Table 5.2).

    The truth is interpolated at the estimate's stamps; stamps outside the truth's span,
    or in a gap of it longer than ``max_gap_s``, are dropped. Position error is the
    Euclidean distance, heading error the wrapped absolute difference. ``std`` is the
    standard deviation of the error magnitudes.
    """
    paired = _paired_poses(stamps, poses, true_stamps, true_poses, max_gap_s)
    return _summary(*_error_magnitudes(*paired))


def pooled_localization_errors(
    trajectories: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    max_gap_s: float = math.inf,
) -> dict[str, float]:
    """:func:`localization_errors` over the samples of several robots' trajectories
    together, each ``(stamps, poses, true_stamps, true_poses)``; ``final_*`` is the last
    robot's."""
    parts = [
        _error_magnitudes(*_paired_poses(*trajectory, max_gap_s)) for trajectory in trajectories
    ]
    return _summary(np.concatenate([d for d, _ in parts]), np.concatenate([y for _, y in parts]))


def team_alignment(
    trajectories: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    max_gap_s: float = math.inf,
) -> dict[str, float | list[float]]:
    """The one rigid motion that best lays the whole team's estimated positions onto the
    truth, and the position RMSE after it; each trajectory ``(stamps, poses, true_stamps,
    true_poses)`` as for :func:`localization_errors`.

    With known start poses the estimate lives in the truth's frame, and the plain RMSE
    counts a rotation of the whole map about the starts (heading error made on the way out
    of the start area, which robots that never come back cannot undo) the same as a map
    that is wrong inside. After the alignment only the latter remains: evo's ``--align``
    without scale (:func:`~acslam.geometry.fit_rigid`), but one transform for all robots,
    since a per-robot alignment would hide how they disagree. Returns the RMSE (m), the
    rotation (rad) and the translation (m) that take the estimate onto the truth (rotation
    about the frame's origin first), and how far the team's mean position moves (m), which
    unlike the translation does not grow with the map's distance from the origin.
    """
    pairs = [_paired_poses(*trajectory, max_gap_s) for trajectory in trajectories]
    estimate = np.concatenate([e[:, :2] for e, _ in pairs])
    truth = np.concatenate([t[:, :2] for _, t in pairs])
    if not len(estimate):
        raise ValueError("the estimated trajectories do not overlap the ground truth in time")
    motion = fit_rigid(estimate, truth)
    rotation_rad = float(motion[2])
    aligned = transform_points(motion, estimate)
    return {
        "aligned_rmse_m": float(np.sqrt(np.mean(np.sum((aligned - truth) ** 2, axis=1)))),
        "rotation_rad": rotation_rad,
        "translation_m": [float(v) for v in motion[:2]],
        "centroid_shift_m": float(np.hypot(*(truth.mean(axis=0) - estimate.mean(axis=0)))),
    }


def confusion_rates(true_occupied: np.ndarray, estimated_values: np.ndarray) -> dict[str, float]:
    """Confusion-based map accuracy over the known cells of the estimate (Table 5.4).

    Positive means occupied. ``estimated_values`` are OccupancyGrid values (-1 unknown,
    0 free, 100 occupied); unknown cells are not scored. Rates with an empty denominator
    are NaN, which JSON writes as null.
    """
    known = estimated_values != UNKNOWN
    predicted = estimated_values == OCCUPIED
    tp = int(np.count_nonzero(known & predicted & true_occupied))
    tn = int(np.count_nonzero(known & ~predicted & ~true_occupied))
    fp = int(np.count_nonzero(known & predicted & ~true_occupied))
    fn = int(np.count_nonzero(known & ~predicted & true_occupied))

    def ratio(num: int, den: int) -> float:
        return num / den if den else float("nan")

    return {
        "accuracy": ratio(tp + tn, tp + tn + fp + fn),
        "tpr": ratio(tp, tp + fn),
        "tnr": ratio(tn, tn + fp),
        "fpr": ratio(fp, fp + tn),
        "fnr": ratio(fn, fn + tp),
        "tp": tp,
        "tn": tn,
        "fp": fp,
        "fn": fn,
    }


def coverage_by_combination(
    explored: Mapping[str, np.ndarray], cell_area_m2: float
) -> dict[str, dict[str, float]]:
    """Explored area of every non-empty combination of robots (Table 5.3).

    ``explored`` maps a robot name to the mask of cells its own scans made known. A
    combination's area is that of the union of its robots' masks; its rate is that area
    over the whole team's, as in the thesis's tables (the full team is 1.0). Keys join
    the names with ``+`` in the given order.
    """
    names = list(explored)
    team_area = np.count_nonzero(np.logical_or.reduce([explored[n] for n in names]))
    result: dict[str, dict[str, float]] = {}
    for size in range(1, len(names) + 1):
        for combo in combinations(names, size):
            union = np.logical_or.reduce([explored[n] for n in combo])
            cells = np.count_nonzero(union)
            result["+".join(combo)] = {
                "area_m2": cells * cell_area_m2,
                "rate": cells / team_area if team_area else 0.0,
            }
    return result


def waste(
    explored: Mapping[str, np.ndarray],
    paths_xy_m: Mapping[str, np.ndarray],
    cell_area_m2: float,
    paths_from: str,
) -> dict[str, object]:
    """What exploring cost beyond the map it made: area seen by more than one robot and
    the distance each robot drove.

    ``explored`` maps a robot name to the mask of cells its own scans made known (as in
    :func:`coverage_by_combination`); the overlap ratio is the area in two or more masks
    over the area in any (0 for one robot). ``paths_xy_m`` maps the same names to (T, 2)
    positions in order; a robot's distance is the length of that polyline.
    ``paths_from`` says whose positions they are (ground truth, or the estimate where a
    real team has none: keyframes only, so shorter than driven).
    """
    seen_by = np.sum([np.asarray(mask, dtype=bool) for mask in explored.values()], axis=0)
    seen_cells = int(np.count_nonzero(seen_by))
    overlap_cells = int(np.count_nonzero(seen_by >= 2))
    travelled_m = {name: path_length_m(xy) for name, xy in paths_xy_m.items()}
    return {
        "overlap_area_m2": overlap_cells * cell_area_m2,
        "overlap_ratio": overlap_cells / seen_cells if seen_cells else 0.0,
        "travelled_m": travelled_m,
        "travelled_total_m": float(sum(travelled_m.values())),
        "travelled_from": paths_from,
    }


def exploration_times(
    explored: bool,
    idle_since_s: Sequence[float | None],
    lost_at_s: Mapping[int, float],
    end_s: float,
) -> list[float | None]:
    """When each robot was done exploring: when it was lost; else, if the team finished,
    when it last became idle (the end if it never did); else None, since it was still
    exploring when the run stopped (at a time limit, on an error)."""
    done_s = [
        (end_s if idle_s is None else idle_s) if explored else None for idle_s in idle_since_s
    ]
    return [lost_at_s.get(i, done) for i, done in enumerate(done_s)]


def timing(finish_times_s: Mapping[str, float | None]) -> dict[str, object]:
    """Exploration time per robot, of the team, and the gap between first and last (Table 5.1).

    A robot still exploring when the run stopped has no exploration time (None): the
    time limit is when the run was cut off, not when the robot was done. The team's
    total and gap are then unknown too.
    """
    times = list(finish_times_s.values())
    unfinished = any(t is None for t in times)
    return {
        "per_robot_s": dict(finish_times_s),
        "total_s": None if unfinished else max(times),
        "gap_s": None if unfinished else max(times) - min(times),
    }


def explored_areas(
    known: np.ndarray, reachable: np.ndarray, cell_area_m2: float
) -> dict[str, float]:
    """The explored area of a run, measured three ways, which differ by design.

    ``mapped_area_m2``: every cell the team map knows (free or occupied): walls count,
    and so do free cells the LiDAR saw where no robot fits. ``reachable_area_m2``: the
    true free area a robot can reach from the starts (what exploring must map).
    ``mapped_reachable_area_m2``: the part of it the map knows, which over the reachable
    area is ``explored_fraction_of_reachable`` (NaN without a reachable cell). Table 5.3's
    team area is a fourth: the union of each robot's own map, which can differ from the
    team map where only the robots' scans together made a cell certain.
    """
    mapped_reachable = int(np.count_nonzero(known & reachable))
    reachable_cells = int(np.count_nonzero(reachable))
    return {
        "mapped_area_m2": int(np.count_nonzero(known)) * cell_area_m2,
        "reachable_area_m2": reachable_cells * cell_area_m2,
        "mapped_reachable_area_m2": mapped_reachable * cell_area_m2,
        "explored_fraction_of_reachable": (
            mapped_reachable / reachable_cells if reachable_cells else math.nan
        ),
    }


def pairwise_precision_recall(truth: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
    """Pairwise association scores: of the measurement pairs put on one estimated landmark,
    the fraction truly one landmark (precision); of the pairs truly one landmark, the
    fraction put on one estimated landmark (recall)."""
    _, t_idx = np.unique(truth, return_inverse=True)
    _, e_idx = np.unique(estimate, return_inverse=True)
    table = np.zeros((t_idx.max() + 1, e_idx.max() + 1))
    np.add.at(table, (t_idx, e_idx), 1)

    def pairs(counts: np.ndarray) -> float:
        return float((counts * (counts - 1) / 2).sum())

    both = pairs(table)
    est_pairs, true_pairs = pairs(table.sum(axis=0)), pairs(table.sum(axis=1))
    return (both / est_pairs if est_pairs else 1.0), (both / true_pairs if true_pairs else 1.0)
