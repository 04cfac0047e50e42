"""Where one robot's frame lies in another's, from sightings that name the robot seen.

A sighting of robot s by robot o (range and bearing, the seen robot known by its
barcode, as in MRCLAM) puts s at ``pose_o (+) point`` in o's frame, while s's own SLAM puts
it at ``pose_s`` in s's frame: one pair of points, the same place in both frames. The
pose of frame B in frame A lays B's points on A's. Pairs are robust to bad ones by RANSAC
over two-pair hypotheses, then fitted in least squares on the inliers
(:func:`~acslam.geometry.fit_rigid`).

A wrong merge is worse than a late one, so a fit is accepted only when it is determined:
enough inliers, few pairs against it, and its covariance (from the residuals, floored at
the sightings' own noise) bounds the error of the frame's pose well inside
``max_error_m`` and ``max_error_rad``. Points all in one place leave the rotation free;
the covariance says so, since the lever arm is the points' spread.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from acslam.geometry import fit_rigid, transform_points


@dataclass(frozen=True)
class AlignmentParams:
    inlier_m: float = 0.25
    """A pair within this of the hypothesis backs it: a sighting's own error (a few cm
    at MRCLAM's ranges) plus how far each robot's own SLAM has drifted from its start."""
    min_inliers: int = 10
    min_inlier_share: float = 0.8
    """Pairs against the fit may be misreads, but a fit most pairs reject is not one."""
    min_pair_spread_m: float = 0.5
    """A hypothesis is drawn from two pairs at least this far apart in B."""
    hypotheses: int = 200
    seed: int = 0
    sighting_sigma_floor_m: float = 0.05
    """The residual scatter of a few pairs can be small by chance; no sighting is better
    than this."""
    max_error_m: float = 0.3
    max_error_rad: float = math.radians(5.0)
    """A fit is accepted when three sigmas of its error fit within these: the error over
    which a merge counts as false (``acslam.eval.frames.FALSE_MERGE_M`` and ``_RAD``)."""
    confidence_sigmas: float = 3.0


@dataclass(frozen=True)
class FrameAlignment:
    """A fit of frame B in frame A: ``pose_b_in_a`` (None when no hypothesis had two
    pairs far enough apart), its inliers, and whether it is accepted and why (not)."""

    pose_b_in_a: np.ndarray | None
    inliers: np.ndarray
    sigmas: np.ndarray
    """``[x, y, theta]`` standard deviations (m, rad) of the pose of B's origin in A."""
    residual_rms_m: float
    spread_m: float
    accepted: bool
    reason: str

    def as_dict(self) -> dict:
        return {
            "pose_b_in_a": None if self.pose_b_in_a is None else self.pose_b_in_a.tolist(),
            "inliers": int(self.inliers.sum()),
            "pairs": len(self.inliers),
            "sigmas": self.sigmas.tolist(),
            "residual_rms_m": self.residual_rms_m,
            "spread_m": self.spread_m,
            "accepted": self.accepted,
            "reason": self.reason,
        }


def _covariance(pose: np.ndarray, points_b: np.ndarray, sigma_m: float) -> np.ndarray:
    """Covariance of ``[x, y, theta]`` of a fit of ``points_b`` with isotropic noise
    ``sigma_m``, by linearising ``R(theta) b + t`` at ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    jacobian = np.zeros((2 * len(points_b), 3))
    jacobian[0::2, 0] = 1.0
    jacobian[1::2, 1] = 1.0
    jacobian[0::2, 2] = -s * points_b[:, 0] - c * points_b[:, 1]
    jacobian[1::2, 2] = c * points_b[:, 0] - s * points_b[:, 1]
    return sigma_m**2 * np.linalg.pinv(jacobian.T @ jacobian)


def _hypotheses(
    points_a: np.ndarray, points_b: np.ndarray, params: AlignmentParams
) -> list[np.ndarray]:
    """Poses fitted to pairs of pairs that are far enough apart in B and keep their
    distance in A (a rigid motion does)."""
    rng = np.random.default_rng(params.seed)
    count = len(points_a)
    first = rng.integers(0, count, params.hypotheses)
    second = rng.integers(0, count, params.hypotheses)
    poses = []
    for i, j in zip(first, second, strict=True):
        distance_b = float(np.linalg.norm(points_b[i] - points_b[j]))
        distance_a = float(np.linalg.norm(points_a[i] - points_a[j]))
        if distance_b < params.min_pair_spread_m or abs(distance_a - distance_b) > params.inlier_m:
            continue
        poses.append(fit_rigid(points_b[[i, j]], points_a[[i, j]]))
    return poses


def align_frames(
    points_a: np.ndarray, points_b: np.ndarray, params: AlignmentParams | None = None
) -> FrameAlignment:
    """The pose of frame B in frame A from (N, 2) pairs of the same places, ``points_a``
    in A and ``points_b`` in B (see the module docstring)."""
    params = params or AlignmentParams()
    points_a, points_b = np.asarray(points_a, float), np.asarray(points_b, float)
    none = np.zeros(len(points_a), dtype=bool)
    if len(points_a) < 2:
        return FrameAlignment(None, none, np.full(3, np.inf), math.nan, 0.0, False, "few pairs")
    best, best_inliers = None, none
    for pose in _hypotheses(points_a, points_b, params):
        errors = np.linalg.norm(transform_points(pose, points_b) - points_a, axis=1)
        inliers = errors <= params.inlier_m
        if inliers.sum() > best_inliers.sum():
            best, best_inliers = pose, inliers
    spread_m = float(np.sqrt(np.mean(np.sum((points_b - points_b.mean(axis=0)) ** 2, axis=1))))
    if best is None:
        return FrameAlignment(
            None, none, np.full(3, np.inf), math.nan, spread_m, False,
            f"no two pairs {params.min_pair_spread_m} m apart that a rigid motion relates",
        )  # fmt: skip
    inliers = best_inliers
    pose = fit_rigid(points_b[inliers], points_a[inliers])
    inliers = np.linalg.norm(transform_points(pose, points_b) - points_a, axis=1) <= params.inlier_m
    if inliers.sum() >= 2:
        pose = fit_rigid(points_b[inliers], points_a[inliers])
    residuals = transform_points(pose, points_b[inliers]) - points_a[inliers]
    count = int(inliers.sum())
    rms_m = float(np.sqrt(np.sum(residuals**2) / max(2 * count - 3, 1)))
    # Pairs from one place share the error of both robots' poses there: they count once.
    places = len(np.unique(np.floor(points_b[inliers] / params.inlier_m), axis=0))
    sigma_m = max(rms_m, params.sighting_sigma_floor_m) * math.sqrt(count / places)
    sigmas = np.sqrt(np.diag(_covariance(pose, points_b[inliers], sigma_m)))
    spread_m = float(
        np.sqrt(np.mean(np.sum((points_b[inliers] - points_b[inliers].mean(axis=0)) ** 2, axis=1)))
    )
    k = params.confidence_sigmas
    if count < params.min_inliers:
        reason = f"{count} inlier pairs, fewer than {params.min_inliers}"
    elif count < params.min_inlier_share * len(inliers):
        reason = f"{count} of {len(inliers)} pairs agree, under {params.min_inlier_share:.0%}"
    elif k * float(np.hypot(sigmas[0], sigmas[1])) > params.max_error_m:
        reason = f"position undetermined ({k:g} sigma {k * np.hypot(*sigmas[:2]):.2f} m)"
    elif k * float(sigmas[2]) > params.max_error_rad:
        reason = f"heading undetermined ({k:g} sigma {math.degrees(k * sigmas[2]):.1f} deg)"
    else:
        return FrameAlignment(pose, inliers, sigmas, rms_m, spread_m, True, "accepted")
    return FrameAlignment(pose, inliers, sigmas, rms_m, spread_m, False, reason)
