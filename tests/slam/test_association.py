"""PDA (eqs. 4.21-4.24) against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from acslam.slam.association import (
    assign_frame,
    euclidean_gate,
    exclusive_probabilities,
    gaussian_likelihood,
    innovation_covariance,
    pose_lever_jacobian,
    score_candidates,
)

LANDMARKS = np.array(
    [
        [0.2, 0.0, 0.0],  # d = (0.2, 0, 0): D = 1 with S = 0.04 I
        [0.0, 0.4, 0.0],  # D = 2
        [1.5, 0.0, 0.0],  # outside the 1 m Euclidean gate
        [0.0, 0.0, 0.8],  # inside the gate, but D^2 = 16 > 11.34
    ]
)
POINT_COV = 0.01 * np.eye(3)
LANDMARK_COV = 0.03 * np.eye(3)
NORM = (2 * math.pi) ** 1.5 * 0.04**1.5  # sqrt((2 pi)^3 |0.04 I|)


def _score(min_likelihood: float):
    gated = euclidean_gate(np.zeros(3), LANDMARKS, 1.0)
    covs = np.repeat(LANDMARK_COV[None], len(gated), axis=0)
    return gated, score_candidates(
        np.zeros(3), POINT_COV, gated, LANDMARKS[gated], covs, 11.34, min_likelihood
    )


def test_gates_and_probabilities() -> None:
    gated, cands = _score(0.0)
    assert list(gated) == [0, 1, 3]
    assert list(cands.indices) == [0, 1]
    np.testing.assert_allclose(cands.mahalanobis, [1.0, 2.0])
    np.testing.assert_allclose(cands.likelihood, [math.exp(-0.5) / NORM, math.exp(-2) / NORM])
    p0 = 1.0 / (1.0 + math.exp(-1.5))
    np.testing.assert_allclose(cands.probability, [p0, 1 - p0])


def test_likelihood_floor_drops_the_weaker_candidate() -> None:
    floor = 0.5 * (math.exp(-0.5) + math.exp(-2)) / NORM
    _, cands = _score(floor)
    assert list(cands.indices) == [0]
    np.testing.assert_allclose(cands.probability, [1.0])


def test_mahalanobis_and_density_of_a_correlated_covariance() -> None:
    cov = np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    d = np.array([1.0, -1.0, 0.0])
    # cov^-1 on (1, -1, 0) = (1, -1, 0) / (2 - 1) -> d^T cov^-1 d = 2; |cov| = 3.
    dist, like = gaussian_likelihood(d, cov)
    assert dist == pytest.approx(math.sqrt(2.0))
    assert like == pytest.approx(math.exp(-1.0) / math.sqrt((2 * math.pi) ** 3 * 3.0))


def test_no_landmarks_no_candidates() -> None:
    assert len(euclidean_gate(np.zeros(3), np.zeros((0, 3)), 1.0)) == 0
    cands = score_candidates(
        np.zeros(3), POINT_COV, np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3, 3)), 11.0, 0.0
    )
    assert len(cands) == 0


def test_frame_assignment_is_mutually_exclusive() -> None:
    """Two points both nearest to landmark 0: only one may take it; the other gets its
    next option (landmark 1), and a point with nothing inside the gate stays unassigned."""
    d2 = np.array([[0.5, 3.0], [1.0, 9.0], [np.inf, 20.0]])
    assert list(assign_frame(d2, 11.34)) == [1, 0, -1]  # 3.0 + 1.0 < 0.5 + 9.0


def test_exclusive_probabilities_ignore_landmarks_taken_by_other_points() -> None:
    d2 = np.array([1.0, 1.0, 4.0])
    log_norm = np.zeros(3)
    cols, p = exclusive_probabilities(d2, log_norm, 11.34, np.array([False, True, False]))
    assert list(cols) == [0, 2]
    p0 = 1.0 / (1.0 + math.exp(-1.5))
    np.testing.assert_allclose(p, [p0, 1 - p0])


def test_a_lone_candidate_under_a_wide_covariance_competes_with_an_unmapped_landmark() -> None:
    """PDA's clutter term: p = N / (N + lambda) for a lone candidate of density N. The same
    squared distance (10.9, inside the 11.34 gate) is near-certain under a tight innovation
    covariance and not under a wide one (the office_d false association: S of about
    0.3 m x 0.3 m x 0.04 m, density 0.12 per m^3)."""
    unmapped = 0.05
    d2 = np.array([10.9])
    for sigmas, expect_sure in (([0.3, 0.3, 0.04], False), ([0.05, 0.05, 0.03], True)):
        log_norm = 0.5 * (3 * math.log(2 * math.pi) + 2 * np.log(sigmas).sum())
        density = math.exp(-0.5 * d2[0] - log_norm)
        cols, p = exclusive_probabilities(
            d2, np.array([log_norm]), 11.34, np.zeros(1, bool), unmapped
        )
        assert list(cols) == [0]
        np.testing.assert_allclose(p, [density / (density + unmapped)])
        assert (p[0] >= 0.9) == expect_sure
    # Without the term a lone candidate is certain, however unlikely the point under it.
    _, p = exclusive_probabilities(d2, np.array([log_norm]), 11.34, np.zeros(1, bool))
    assert p[0] == 1.0


def test_cross_covariance_cancels_shared_drift() -> None:
    """Pose and landmark that drifted together (cross-covariance = their covariance):
    the innovation covariance is just the measurement's."""
    lever = pose_lever_jacobian(np.eye(3), np.array([1.0, 0.0, 0.0]))
    pose_cov = np.diag([0.5, 0.5, 1e-9])  # translation drift only
    landmark_cov = lever @ pose_cov @ lever.T
    cross = pose_cov @ lever.T
    meas = 0.01 * np.eye(3)
    s = innovation_covariance(lever, pose_cov, landmark_cov, cross, meas)
    np.testing.assert_allclose(s, meas, atol=1e-8)
    s_ignored = innovation_covariance(lever, pose_cov, landmark_cov, None, meas)
    assert s_ignored[0, 0] > 1.0
