"""Frame alignment from sightings: recovers a known motion through outliers, and refuses
fits that the pairs do not determine."""

from __future__ import annotations

import math

import numpy as np

from acslam.geometry import transform_points, wrap_angle
from acslam.slam.frame_alignment import align_frames

TRUE_POSE = np.array([3.0, -1.5, 2.2])
"""Frame B's origin in frame A."""


def _pairs(points_b: np.ndarray, noise_m: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return transform_points(TRUE_POSE, points_b) + rng.normal(0.0, noise_m, points_b.shape)


def test_recovers_the_motion_through_a_fifth_of_misreads() -> None:
    rng = np.random.default_rng(1)
    points_b = rng.uniform(-2.0, 2.0, (60, 2))
    points_a = _pairs(points_b, 0.03, seed=2)
    misread = np.arange(60) % 5 == 0
    points_a[misread] += rng.uniform(1.0, 3.0, (misread.sum(), 2))
    fit = align_frames(points_a, points_b)
    assert fit.accepted, fit.reason
    assert fit.pose_b_in_a is not None
    assert np.hypot(*(fit.pose_b_in_a[:2] - TRUE_POSE[:2])) < 0.03
    assert abs(wrap_angle(fit.pose_b_in_a[2] - TRUE_POSE[2])) < math.radians(0.5)
    np.testing.assert_array_equal(fit.inliers, ~misread)
    # 48 inliers over an RMS spread of ~1.6 m with 3 cm noise: sigma_theta ~ 0.03 / (1.6
    # sqrt(48)) = 0.003 rad, well inside the bound.
    assert fit.sigmas[2] < 0.01


def test_pairs_at_one_place_leave_the_heading_open() -> None:
    """A teammate seen many times from one spot: its position is known, the frame's
    heading is not, whatever the count."""
    points_b = np.tile([[1.0, 2.0]], (40, 1)) + np.random.default_rng(3).normal(0, 0.02, (40, 2))
    fit = align_frames(_pairs(points_b, 0.02, seed=4), points_b)
    assert not fit.accepted
    assert "apart" in fit.reason or "heading" in fit.reason


def test_pairs_from_two_places_count_as_two_not_as_their_number() -> None:
    """Two places 0.6 m apart, each seen 30 times: the error of both robots' poses at each
    place is shared by its pairs, so the heading is known to about 0.05 m / 0.3 m (10
    degrees), not to that over sqrt(60)."""
    rng = np.random.default_rng(5)
    places = np.array([[0.0, 0.0], [0.6, 0.0]])
    points_b = np.repeat(places, 30, axis=0) + rng.normal(0, 0.01, (60, 2))
    fit = align_frames(_pairs(points_b, 0.05, seed=6), points_b)
    assert not fit.accepted and "undetermined" in fit.reason
    spread = np.repeat(rng.uniform(-2.0, 2.0, (30, 2)), 2, axis=0)
    fit = align_frames(_pairs(spread, 0.05, seed=7), spread)
    assert fit.accepted, fit.reason


def test_pairs_that_half_disagree_merge_nothing() -> None:
    """Half the pairs follow another motion: no fit most pairs back."""
    rng = np.random.default_rng(8)
    points_b = rng.uniform(-2.0, 2.0, (40, 2))
    points_a = _pairs(points_b, 0.02, seed=9)
    points_a[20:] = transform_points(np.array([-1.0, 2.0, 0.4]), points_b[20:])
    fit = align_frames(points_a, points_b)
    assert not fit.accepted and "agree" in fit.reason
