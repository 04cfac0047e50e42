"""SLAM accuracy on relations between poses (Kümmerle et al. 2009), in Freiburg's format.

A relations file holds one relation per line, ``t1 t2 x y z roll pitch yaw``: the pose at
time ``t2`` expressed in the frame of the pose at time ``t1`` (metres, radians), checked by
hand against the laser data. The metric compares each with the same relative pose of the
estimate, so a trajectory is scored without a global ground truth and a local error is not
charged again at every later pose, unlike an absolute trajectory error. Cartographer
(Hess et al. 2016, Table II) and the Freiburg evaluator report the mean and standard
deviation of the translational (m) and rotational (deg) error over the relations.

Relations are planar here: ``z``, ``roll`` and ``pitch`` must be 0, as a 2D log's
relations have them; a file that is not planar is refused rather than projected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from acslam.errors import DataError
from acslam.files import atomic_path
from acslam.geometry import between_rows

DEFAULT_MAX_GAP_S = 0.01
"""How far an estimated pose's stamp may lie from a relation's: less than half the frame
period of a 40 Hz laser, so a relation never takes a neighbouring scan's pose."""


@dataclass(frozen=True)
class Relations:
    """Relations ``first_s[k] -> second_s[k]``: ``relative[k]`` is ``[x, y, yaw]`` of the
    second pose in the first's frame."""

    first_s: np.ndarray
    second_s: np.ndarray
    relative: np.ndarray

    def __len__(self) -> int:
        return len(self.first_s)


def read_relations(path: Path) -> Relations:
    """The relations of a Freiburg file, or one error naming the file and the line."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(path, f"not a relations file ({exc})") from None
    rows = []
    for number, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            raise DataError(path, f"not numbers: {text!r}", number) from None
        if len(values) != 8:
            raise DataError(path, f"a relation needs 8 numbers (t1 t2 x y z roll pitch yaw), "
                                  f"this line has {len(values)}", number)  # fmt: skip
        if not all(math.isfinite(v) for v in values):
            raise DataError(path, "a relation's numbers must be finite", number)
        if any(abs(values[k]) > 1e-9 for k in (4, 5, 6)):
            raise DataError(path, "not planar: z, roll and pitch must be 0", number)
        rows.append(values)
    if not rows:
        raise DataError(path, "no relations in the file")
    table = np.array(rows)
    return Relations(table[:, 0], table[:, 1], table[:, [2, 3, 7]])


def write_relations(path: Path, relations: Relations) -> None:
    """Write relations in the Freiburg format (read back exactly by :func:`read_relations`)."""
    zeros = np.zeros(len(relations))
    x, y, yaw = relations.relative.T
    table = np.column_stack([relations.first_s, relations.second_s, x, y, zeros, zeros, zeros, yaw])
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        np.savetxt(temporary, table, fmt="%.9f")


def relations_from_truth(
    stamps_s: np.ndarray,
    poses: np.ndarray,
    every_s: float,
    revisit_radius_m: float,
    min_loop_m: float,
) -> Relations:
    """Relations from a true trajectory, as a simulator writes them for a log of its own.

    The truth is sampled every ``every_s``; each sample is related to the next (local
    accuracy, what odometry and scan matching decide) and to every earlier sample within
    ``revisit_radius_m`` that the robot left by at least ``min_loop_m`` of path before it
    came back (a revisit, what loop closure decides; a robot turning on the spot revisits
    nothing). Deterministic: the same truth gives the same file.
    """
    stamps_s, poses = np.asarray(stamps_s, float), np.asarray(poses, float)
    picked = [0]
    for k in range(1, len(stamps_s)):
        if stamps_s[k] - stamps_s[picked[-1]] >= every_s:
            picked.append(k)
    steps_m = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    arc_m = np.concatenate(([0.0], np.cumsum(steps_m)))[picked]
    xy = poses[picked, :2]
    pairs = [(picked[n], picked[n + 1]) for n in range(len(picked) - 1)]
    for n in range(1, len(picked)):
        near = np.hypot(*(xy[:n] - xy[n]).T) <= revisit_radius_m
        left = arc_m[n] - arc_m[:n] >= min_loop_m
        pairs += [(picked[m], picked[n]) for m in np.flatnonzero(near & left)]
    if not pairs:
        raise ValueError(f"a truth shorter than {every_s:g} s has no relations")
    first, second = np.array(pairs).T
    return Relations(stamps_s[first], stamps_s[second], between_rows(poses[first], poses[second]))


def _nearest(stamps_s: np.ndarray, wanted_s: np.ndarray, max_gap_s: float) -> np.ndarray:
    """Index of the stamp nearest each wanted time, or -1 if none lies within ``max_gap_s``."""
    right = np.searchsorted(stamps_s, wanted_s).clip(1, len(stamps_s) - 1)
    left = right - 1
    pick = np.where(
        np.abs(stamps_s[left] - wanted_s) <= np.abs(stamps_s[right] - wanted_s), left, right
    )
    return np.where(np.abs(stamps_s[pick] - wanted_s) <= max_gap_s, pick, -1)


def _sample_std(values: np.ndarray) -> float:
    return float(values.std(ddof=1)) if len(values) > 1 else math.nan


def relation_errors(
    stamps_s: np.ndarray,
    poses: np.ndarray,
    relations: Relations,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
) -> dict[str, float | int]:
    """Translational and rotational error of a trajectory on the relations.

    Each relation's two times take the estimated poses nearest in time (within
    ``max_gap_s``); a relation whose times the trajectory does not cover is not matched,
    and the share matched is reported beside the errors. The error of relation ``k`` is
    ``d_ref^-1 * d_est`` of the estimated and reference relative poses (``d_est ⊖ d_ref``
    of Kümmerle et al.): its translation's norm (m) and its angle's magnitude (deg).
    Cartographer's evaluator composes ``d_est * d_ref^-1`` instead, whose translation
    differs by at most the relation's length times the angle error: the same figure to
    first order. Means, sample standard deviations (n - 1, NaN for one relation, as
    Cartographer's) and mean squares over the matched relations.
    """
    order = np.argsort(stamps_s, kind="stable")
    stamps_s, poses = np.asarray(stamps_s, float)[order], np.asarray(poses, float)[order]
    if len(stamps_s) < 2:
        raise ValueError("a trajectory of fewer than 2 poses has no relations to score")
    first = _nearest(stamps_s, relations.first_s, max_gap_s)
    second = _nearest(stamps_s, relations.second_s, max_gap_s)
    matched = (first >= 0) & (second >= 0)
    if not matched.any():
        raise ValueError(
            f"no relation's times lie within {max_gap_s:g} s of the trajectory's stamps "
            f"({stamps_s[0]:.3f}-{stamps_s[-1]:.3f} s)"
        )
    estimated = between_rows(poses[first[matched]], poses[second[matched]])
    errors = between_rows(relations.relative[matched], estimated)
    translation_m = np.hypot(errors[:, 0], errors[:, 1])
    rotation_deg = np.degrees(np.abs(errors[:, 2]))  # between_rows wraps the angle
    return {
        "relations": len(relations),
        "matched": int(matched.sum()),
        "matched_fraction": float(matched.mean()),
        "translation_mean_m": float(translation_m.mean()),
        "translation_std_m": _sample_std(translation_m),
        "translation_mean_square_m2": float(np.mean(translation_m**2)),
        "rotation_mean_deg": float(rotation_deg.mean()),
        "rotation_std_deg": _sample_std(rotation_deg),
        "rotation_mean_square_deg2": float(np.mean(rotation_deg**2)),
    }
