"""Probabilistic data association (thesis §4.4.2, eqs. 4.21-4.24), as pure functions.

The thesis innovation d = z - l_j (eq. 4.21) compares a robot-frame measurement with a
world-frame landmark; we first map z into the world with the current pose estimate, so
d = T_i z - l_j. Its covariance is S = Sigma_lj + R Sigma_z R^T + J Sigma_pose J^T: the
landmark's marginal, the measurement noise, and the pose uncertainty pushed through the
lever arm (the thesis uses Sigma_j alone, which is singular-ish for a fresh landmark and
overconfident for a drifting robot). ``score_candidates`` neglects the pose-landmark
cross-covariance; the per-frame functions at the end (used by the back end) include it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Candidates:
    """Surviving candidates of one measurement: indices into the landmark list and scores."""

    indices: np.ndarray
    mahalanobis: np.ndarray
    likelihood: np.ndarray
    probability: np.ndarray
    nearest_mahalanobis: float

    def __len__(self) -> int:
        return len(self.indices)


def euclidean_gate(point: np.ndarray, landmarks: np.ndarray, gate_m: float) -> np.ndarray:
    """Indices of the (M, 3) ``landmarks`` within ``gate_m`` of ``point`` (cheap first cut)."""
    if len(landmarks) == 0:
        return np.zeros(0, dtype=int)
    distance = np.linalg.norm(landmarks - point, axis=1)
    return np.flatnonzero(distance <= gate_m)


def pose_lever_jacobian(rotation: np.ndarray, point_body: np.ndarray) -> np.ndarray:
    """d(T p)/d xi for a Pose2 right perturbation xi = [v_x, v_y, omega] of a 3D point
    (3x3): R [I, [-p_y, p_x]] in the plane, nothing on z. ``rotation`` is the pose's 3x3
    rotation about z."""
    jacobian = np.zeros((3, 3))
    jacobian[:2, :2] = rotation[:2, :2]
    jacobian[:2, 2] = rotation[:2, :2] @ np.array([-point_body[1], point_body[0]])
    return jacobian


def measurement_covariance(
    rotation: np.ndarray,
    point_body: np.ndarray,
    measurement_cov_body: np.ndarray,
    pose_cov: np.ndarray,
) -> np.ndarray:
    """World-frame covariance of T p: R Sigma_z R^T + J Sigma_pose J^T."""
    jac = pose_lever_jacobian(rotation, point_body)
    return rotation @ measurement_cov_body @ rotation.T + jac @ pose_cov @ jac.T


def gaussian_likelihood(innovation: np.ndarray, covariance: np.ndarray) -> tuple[float, float]:
    """Mahalanobis distance (eq. 4.22) and Gaussian density (eq. 4.23) of an innovation."""
    d2 = float(innovation @ np.linalg.solve(covariance, innovation))
    dim = len(innovation)
    norm = math.sqrt((2.0 * math.pi) ** dim * float(np.linalg.det(covariance)))
    return math.sqrt(max(d2, 0.0)), math.exp(-0.5 * d2) / norm


def score_candidates(
    point_world: np.ndarray,
    point_cov: np.ndarray,
    indices: np.ndarray,
    landmarks: np.ndarray,
    landmark_covs: np.ndarray,
    mahalanobis_gate_sq: float,
    min_likelihood: float,
) -> Candidates:
    """Eqs. 4.21-4.24 on the Euclidean-gated ``indices``.

    ``landmarks`` (K, 3) and ``landmark_covs`` (K, 3, 3) belong to ``indices``. Candidates
    with D^2 above the gate or a density below ``min_likelihood`` are dropped, the rest get
    probabilities proportional to their likelihoods (summing to 1). ``nearest_mahalanobis``
    is the smallest D over all gated landmarks, kept or not (inf if none), so the caller can
    tell "clearly new" from "ambiguous".
    """
    keep, dists, likes = [], [], []
    nearest = math.inf
    for k, index in enumerate(indices):
        innovation = point_world - landmarks[k]
        dist, like = gaussian_likelihood(innovation, landmark_covs[k] + point_cov)
        nearest = min(nearest, dist)
        if dist * dist <= mahalanobis_gate_sq and like > 0.0 and like >= min_likelihood:
            keep.append(int(index))
            dists.append(dist)
            likes.append(like)
    likelihood = np.array(likes, dtype=float)
    probability = likelihood / likelihood.sum() if len(likelihood) else likelihood
    return Candidates(np.array(keep, dtype=int), np.array(dists), likelihood, probability, nearest)


# ---------------------------------------------------------------------- joint (per frame)
#
# The per-point PDA above treats the points of one camera frame independently, so two
# points can both pull on one landmark and every point near two landmarks spreads its
# weight over both. The functions below associate a whole frame at once:
#
# 1. ``assign_frame``: a gated assignment (Hungarian on squared Mahalanobis distances, with
#    a "no landmark" option of cost = the gate) so that two points of one frame never go
#    to the same landmark (mutual exclusion; one landmark makes at most one point).
# 2. ``exclusive_probabilities``: eqs. 4.23-4.24 evaluated only among the candidates that
#    no *other* point of the frame took; the caller then skips a point whose assigned
#    candidate does not clearly dominate (ambiguity -> no factor rather than spread weight).


def innovation_covariance(
    lever: np.ndarray,
    pose_cov: np.ndarray,
    landmark_cov: np.ndarray,
    cross_cov: np.ndarray | None,
    measurement_cov_world: np.ndarray,
) -> np.ndarray:
    """Covariance of d = T p - l for a landmark l and a pose T (right perturbation).

    ``lever`` is d(T p)/d xi (3x3, :func:`pose_lever_jacobian`), ``cross_cov`` the 3x3
    pose-landmark block of their joint marginal (None: neglected). With a re-observed
    landmark the cross term cancels most of the shared drift: S is the uncertainty of the
    landmark *relative to the robot*, not the sum of the two absolute uncertainties.
    """
    s = lever @ pose_cov @ lever.T + landmark_cov + measurement_cov_world
    if cross_cov is not None:
        lc = lever @ cross_cov
        s = s - lc - lc.T
    return 0.5 * (s + s.T)


def mahalanobis_sq(innovation: np.ndarray, covariance: np.ndarray) -> float:
    """d^T S^-1 d; inf if S is not positive definite."""
    try:
        chol = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        return math.inf
    y = np.linalg.solve(chol, innovation)
    return float(y @ y)


def assign_frame(d2: np.ndarray, gate_sq: float) -> np.ndarray:
    """Gated one-to-one assignment of the N points of a frame to M candidates.

    ``d2`` (N, M) holds squared Mahalanobis distances (inf where not a candidate). Returns
    (N,) column indices, -1 for "no landmark". Minimises the sum of d2 over assigned pairs
    plus ``gate_sq`` per unassigned point, so no pair above the gate is ever used.
    """
    from scipy.optimize import linear_sum_assignment

    n, m = d2.shape
    out = np.full(n, -1, dtype=int)
    if n == 0 or m == 0:
        return out
    big = 1e9
    cost = np.full((n, m + n), big)
    real = np.where(d2 <= gate_sq, d2, big)
    cost[:, :m] = real
    cost[np.arange(n), m + np.arange(n)] = gate_sq
    rows, cols = linear_sum_assignment(cost)
    for r, c in zip(rows, cols, strict=True):
        if c < m and cost[r, c] < big:
            out[r] = c
    return out


def exclusive_probabilities(
    d2_row: np.ndarray,
    log_norm_row: np.ndarray,
    gate_sq: float,
    taken_by_others: np.ndarray,
    unmapped_density: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4.23-4.24 among one point's exclusive candidates, beside the hypothesis that
    the point belongs to none of them.

    ``log_norm_row`` holds log sqrt((2 pi)^3 |S|) per column. ``unmapped_density`` (1/m^3)
    is the density of a point from no mapped landmark (one not mapped yet, or a false
    detection): PDA's clutter term, which the thesis leaves out. Without it a lone
    candidate gets probability 1 however unlikely the point is under it: on IPA
    office_d, a landmark not yet mapped, 1.1 m from a mapped one, was taken for it once
    a robot's pose covariance was wide enough to gate it, and the factor moved the robot's
    estimate 0.8 m. Returns the candidate columns (gated, not assigned to another point of
    the frame) and their probabilities (computed in log space, so tiny densities do not
    underflow), which sum to less than 1 by what the unmapped hypothesis takes.
    """
    ok = np.isfinite(d2_row) & (d2_row <= gate_sq) & ~taken_by_others
    cols = np.flatnonzero(ok)
    if len(cols) == 0:
        return cols, np.zeros(0)
    log_like = -0.5 * d2_row[cols] - log_norm_row[cols]
    log_unmapped = math.log(unmapped_density) if unmapped_density > 0.0 else -math.inf
    top = max(float(log_like.max()), log_unmapped)
    like = np.exp(log_like - top)
    return cols, like / (like.sum() + math.exp(log_unmapped - top))
