"""Probabilistic data association (thesis §4.4.2, eqs. 4.21-4.24), as pure functions.

The thesis innovation d = z - l_j (eq. 4.21) compares a robot-frame measurement with a
world-frame landmark; we first map z into the world with the current pose estimate, so
d = T_i z - l_j. Its covariance is S = Sigma_lj + R Sigma_z R^T + J Sigma_pose J^T: the
landmark's marginal, the measurement noise, and the pose uncertainty pushed through the
lever arm (the thesis uses Sigma_j alone, which is singular-ish for a fresh landmark and
overconfident for a drifting robot). The pose-landmark cross-covariance is neglected.
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
    """d(T p)/d xi for a Pose3 right perturbation xi = [omega, v]: R [-[p]x, I] (3x6)."""
    px, py, pz = point_body
    skew = np.array([[0.0, -pz, py], [pz, 0.0, -px], [-py, px, 0.0]])
    return rotation @ np.hstack([-skew, np.eye(3)])


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
