"""The back end on small synthetic multi-robot problems built directly from messages."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg

from acslam.config import SlamConfig
from acslam.errors import SlamError
from acslam.eval.metrics import pairwise_precision_recall
from acslam.geometry import between, compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement
from acslam.slam import keys
from acslam.slam.backend import SlamBackend

DT = 0.1
# Landmarks on a 1.5 m lattice: far apart relative to the 1 m gate and 3 cm noise, so the
# association is unambiguous and the test is about the estimator.
LANDMARKS = np.array(
    [[x, y, 0.3] for x in np.arange(-1.5, 7.6, 1.5) for y in np.arange(-3.0, 3.1, 1.5)]
)
SENSOR_RANGE_M = 2.5


def _circle_truth(start: np.ndarray, v: float, omega: float, steps: int) -> np.ndarray:
    poses = [start]
    for _ in range(steps):
        poses.append(compose(poses[-1], np.array([v * DT, 0.0, omega * DT])))
    return np.array(poses)


def _feed(
    backend: SlamBackend,
    truths: dict[int, np.ndarray],
    rng: np.random.Generator | None,
    odom_sigma: float = 0.0,
    point_sigma: float = 0.0,
    update_every: int = 10,
) -> None:
    steps = len(next(iter(truths.values()))) - 1
    for k in range(1, steps + 1):
        for robot, truth in truths.items():
            delta = between(truth[k - 1], truth[k])
            if rng is not None:
                delta = delta + rng.normal(scale=odom_sigma, size=3) * [1, 1, 1]
            backend.add_odometry(OdometryIncrement(robot, k * DT, (k - 1) * DT, *delta))
            pose = truth[k]
            c, s = math.cos(pose[2]), math.sin(pose[2])
            rel = LANDMARKS - [pose[0], pose[1], 0.0]
            body = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
            body = np.column_stack([body, rel[:, 2]])
            seen = body[np.linalg.norm(body[:, :2], axis=1) < SENSOR_RANGE_M]
            if rng is not None:
                seen = seen + rng.normal(scale=point_sigma, size=seen.shape)
            if k % 2 == 0:
                backend.add_landmarks(LandmarkObservations(robot, k * DT, seen))
        if k % update_every == 0:
            backend.update()
    backend.update()


def _team() -> dict[int, np.ndarray]:
    return {
        0: _circle_truth(np.array([0.0, 0.0, 0.0]), 0.3, 0.15, 300),
        1: _circle_truth(np.array([3.0, -1.0, math.pi / 2]), 0.25, -0.1, 300),
        2: _circle_truth(np.array([6.0, 1.0, math.pi]), 0.2, 0.0, 300),
    }


def test_noiseless_measurements_recover_the_truth_exactly() -> None:
    truths = _team()
    backend = SlamBackend(SlamConfig(), {r: t[0] for r, t in truths.items()})
    _feed(backend, truths, rng=None)
    for robot, truth in truths.items():
        stamps, poses = backend.trajectory(robot)
        rows = np.rint(stamps / DT).astype(int)
        np.testing.assert_allclose(poses[:, :2], truth[rows, :2], atol=1e-6)
        np.testing.assert_allclose(backend.latest_pose(robot), truth[-1], atol=1e-6)
    lms = backend.landmarks()
    # Every landmark estimate sits on a true landmark; none is duplicated.
    nearest = np.linalg.norm(lms[:, None] - LANDMARKS[None], axis=2).min(axis=1)
    assert nearest.max() < 1e-6
    assert len(lms) == len({tuple(np.round(p, 3)) for p in lms})


def test_noisy_optimum_is_consistent_with_its_covariance() -> None:
    """Bound: each robot's final pose error must lie inside the estimator's own 99.9 % region.

    With Gaussian noise the MAP error is ~N(0, P) with P the reported covariance (the
    linearisation is mild at these noise levels), so e^T P^-1 e follows chi-square with
    3 dof: 16.27 is its 99.9 % quantile. The config sigmas are set to the simulated ones.
    """
    odom_sigma, point_sigma = 0.003, 0.03
    config = SlamConfig(
        landmark_sigma_m=point_sigma,
        odom_sigma_min_xy_m=odom_sigma * math.sqrt(3),
        odom_sigma_min_theta_rad=odom_sigma * math.sqrt(3),
        odom_sigma_xy_per_m=0.03,
        odom_sigma_theta_per_rad=0.03,
        odom_sigma_theta_per_m=0.03,
    )
    truths = _team()
    backend = SlamBackend(config, {r: t[0] for r, t in truths.items()})
    _feed(backend, truths, np.random.default_rng(7), odom_sigma, point_sigma)
    for robot, truth in truths.items():
        err = backend.latest_pose(robot) - truth[-1]
        err[2] = (err[2] + math.pi) % (2 * math.pi) - math.pi
        d2 = err @ np.linalg.solve(backend.latest_covariance(robot), err)
        assert d2 < 16.27, (robot, err, d2)
        assert np.hypot(*err[:2]) < 0.1
    # Lattice landmarks seen at 3 cm noise from many poses: well below the noise.
    lms = backend.landmarks()
    nearest = np.linalg.norm(lms[:, None] - LANDMARKS[None], axis=2).min(axis=1)
    assert np.sqrt(np.mean(nearest**2)) < point_sigma


def _drive_robot_1_short(backend: SlamBackend, start: np.ndarray) -> np.ndarray:
    """Drive robot 1 3 m straight at 0.1 m per step with odometry reading 0.09 m (10 %
    short), updating every 5 steps; returns its true final pose."""
    truth = start
    for k in range(1, 31):
        truth = compose(truth, np.array([0.1, 0.0, 0.0]))
        backend.add_odometry(OdometryIncrement(1, k * DT, (k - 1) * DT, 0.09, 0.0, 0.0))
        if k % 5 == 0:
            backend.update()
    return truth


def test_shared_landmarks_correct_another_robots_drift() -> None:
    """Robot 0 maps three landmarks from its known start; robot 1's odometry under-reads
    distance by 10 %. When robot 1 sees robot 0's landmarks, its pose snaps back.

    Config: odometry sigma 10 % of distance (the bias is then 1 sigma, so the Mahalanobis
    gate accepts the association) and a 2 cm camera, so the landmarks (seen from a prior-
    pinned pose) are ~10x more certain than robot 1's 3 m of odometry and the MAP pulls it
    almost fully onto them: residual ~ 0.3 m * (1.2^2 / (1.2^2 + 9.5^2)) cm ~ 5 mm.
    """
    shared = np.array([[2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [3.0, -0.5, 0.0]])
    config = SlamConfig(odom_sigma_xy_per_m=0.1, landmark_sigma_m=0.02)
    backend = SlamBackend(config, {0: np.zeros(3), 1: np.array([-2.0, -1.5, 0.0])})
    for k in range(config.landmark_confirmations):  # new landmarks need re-observations
        backend.add_landmarks(LandmarkObservations(0, 0.01 * k, shared))
    backend.update()
    truth1 = np.array([-2.0, -1.5, 0.0])
    truth1 = _drive_robot_1_short(backend, truth1)
    before = backend.latest_pose(1)
    assert before[0] - truth1[0] == pytest.approx(-0.3, abs=1e-9)
    body = shared - [truth1[0], truth1[1], 0.0]
    results = backend.add_landmarks(LandmarkObservations(1, 3.05, body))
    assert [r.landmark for r in results] == [0, 1, 2]
    backend.update(extra_iterations=4)  # Huber reweighting needs a few Gauss-Newton steps
    moved = backend.moved_keyframes()
    after = backend.latest_pose(1)
    assert np.hypot(*(after - truth1)[:2]) < 0.05
    assert {r for r, _ in moved} == {1}
    assert len(moved) >= backend.keyframe_count(1) // 2
    np.testing.assert_allclose(backend.trajectory(0)[1][0], np.zeros(3), atol=0.02)


def test_seeing_another_robot_corrects_its_drift() -> None:
    """Robot 0 stands at its known start; robot 1's odometry under-reads distance by 10 %
    over 3 m. Robot 0 then measures robot 1 (exact point), with robot 1 0.18 m past its
    latest keyframe, so the offset path is used: robot 1's pose snaps back.

    Config as in the landmark case above: odometry sigma 10 % of distance and a 2 cm
    camera, so the sighting is ~5x more certain than robot 1's odometry chain and the MAP
    moves it almost fully (a few cm left), while robot 0 (prior-pinned) stays put.
    """
    config = SlamConfig(odom_sigma_xy_per_m=0.1, landmark_sigma_m=0.02)
    truth1 = np.array([0.5, 1.0, 0.0])
    backend = SlamBackend(config, {0: np.zeros(3), 1: truth1})
    truth1 = _drive_robot_1_short(backend, truth1)
    before = backend.latest_pose(1)
    assert before[0] - truth1[0] == pytest.approx(-0.3, abs=1e-9)
    assert backend.keyframe_count(1) == 8  # a keyframe every 4 steps: 0.18 m past the last
    assert backend.add_robot_observation(0, 1, 3.05, np.array([*truth1[:2], 0.0]))
    assert backend.association.robot_observations == 1
    backend.update(extra_iterations=4)  # Huber reweighting needs a few Gauss-Newton steps
    after = backend.latest_pose(1)
    assert np.hypot(*(after - truth1)[:2]) < 0.05
    np.testing.assert_allclose(backend.latest_pose(0), np.zeros(3), atol=0.01)
    # Out of order from the same observer: skipped and counted; unknown robots are errors.
    assert not backend.add_robot_observation(0, 1, 3.0, np.array([3.5, 1.0, 0.0]))
    assert backend.skipped_messages["robots"] == 1
    with pytest.raises(SlamError, match="robot 7"):
        backend.add_robot_observation(0, 7, 4.0, np.array([1.0, 0.0, 0.0]))


def test_keyframes_grow_with_distance_not_time() -> None:
    backend = SlamBackend(SlamConfig(keyframe_distance_m=0.3), {0: np.zeros(3)})
    for k in range(1, 1001):  # 100 s standing still, observing
        backend.add_odometry(OdometryIncrement(0, k * DT, (k - 1) * DT, 0.0, 0.0, 0.0))
        backend.add_landmarks(LandmarkObservations(0, k * DT, np.array([[1.0, 0.0, 0.0]])))
    backend.update()
    assert backend.keyframe_count(0) == 1
    for k in range(1001, 1031):  # then 3 m in 3 s
        backend.add_odometry(OdometryIncrement(0, k * DT, (k - 1) * DT, 0.1, 0.0, 0.0))
    backend.update()
    assert backend.keyframe_count(0) == 11
    assert len(backend.landmarks()) == 1


def test_odometry_chain_covariance_sums_the_keyframes() -> None:
    """Three 0.5 m keyframes straight on (sigmas 0.025 m and 0.02 rad each with these
    settings): from keyframe 0 to 3 the heading variance is 3 x 0.02^2 and x, y add the
    position variances plus the heading's over the 1.5 m chain, 3 x 0.025^2 + 3 x 0.02^2
    x 1.5^2; from 1 to 2, one keyframe's."""
    config = SlamConfig(
        keyframe_distance_m=0.5,
        odom_sigma_xy_per_m=0.05,
        odom_sigma_theta_per_m=0.04,
        odom_sigma_theta_per_rad=0.05,
    )
    backend = SlamBackend(config, {0: np.zeros(3)})
    for k in range(1, 16):
        backend.add_odometry(OdometryIncrement(0, k * DT, (k - 1) * DT, 0.1, 0.0, 0.0))
    assert backend.keyframe_count(0) == 4
    chain = backend.odometry_chain_covariance(0, 0, 3)
    var_xy = 3 * 0.025**2 + 3 * 0.02**2 * 1.5**2
    assert np.allclose(chain, np.diag([var_xy, var_xy, 3 * 0.02**2]))
    one = backend.odometry_chain_covariance(0, 1, 2)
    assert np.allclose(one, np.diag([0.025**2 + 0.02**2 * 0.25, 0.025**2 + 0.02**2 * 0.25, 4e-4]))


def test_time_going_backwards_is_skipped_and_counted() -> None:
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    backend.add_odometry(OdometryIncrement(0, 1.0, 0.9, 0.1, 0.0, 0.0))
    backend.add_odometry(OdometryIncrement(0, 0.5, 0.4, 0.1, 0.0, 0.0))
    assert backend.skipped_messages["odometry"] == 1
    np.testing.assert_allclose(backend.latest_pose(0), [0.1, 0.0, 0.0])
    with pytest.raises(SlamError, match="robot 4"):
        backend.add_odometry(OdometryIncrement(4, 1.0, 0.9, 0.1, 0.0, 0.0))


def test_posed_scans_follow_their_keyframe() -> None:
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    scan = LidarScan(0, 0.0, np.zeros(4), np.ones(4), 8.0)
    backend.add_odometry(OdometryIncrement(0, 0.1, 0.0, 0.1, 0.0, 0.0))
    backend.add_scan(scan)
    backend.update()
    ((stored, pose),) = backend.scans.posed()
    assert stored is scan
    np.testing.assert_allclose(pose, [0.1, 0.0, 0.0], atol=1e-9)


def test_gtsam_failures_become_slam_errors() -> None:
    class Exploding:
        def update(self, *args: object) -> None:
            raise RuntimeError("Indeterminant linear system detected near variable x0")

    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    backend._isam = Exploding()  # simulate GTSAM's C++ exception as pybind raises it
    with pytest.raises(SlamError, match="Indeterminant"):
        backend.update()


def test_closely_spaced_landmarks_keep_their_identities() -> None:
    """Landmarks in pairs 0.25 m apart (under 10x the 3 cm camera noise), a robot with
    biased odometry driving a circle among them: association precision >= 0.95 against
    the true ids (pairwise, as for MRCLAM), and no landmark merged with its twin."""
    rng = np.random.default_rng(11)
    centres = np.array([[x, y] for x in (-1.5, 0.0, 1.5) for y in (-1.5, 1.5)] + [[3.0, 0.0]])
    pairs = []
    for cx, cy in centres:
        a = rng.uniform(0, math.pi)
        d = 0.125 * np.array([math.cos(a), math.sin(a)])
        pairs += [[cx + d[0], cy + d[1], 0.3], [cx - d[0], cy - d[1], 0.3]]
    truth_lms = np.array(pairs)
    config = SlamConfig(landmark_sigma_m=0.03, odom_sigma_xy_per_m=0.05)
    truth = _circle_truth(np.array([0.0, -2.5, 0.0]), 0.3, 0.12, 600)
    backend = SlamBackend(config, {0: truth[0]})
    labels, estimates = [], []
    for k in range(1, len(truth)):
        delta = between(truth[k - 1], truth[k]) * np.array([1.04, 1.0, 1.03])  # biased
        backend.add_odometry(OdometryIncrement(0, k * DT, (k - 1) * DT, *delta))
        if k % 2:
            continue
        pose = truth[k]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        rel = truth_lms - [pose[0], pose[1], 0.0]
        body = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
        body = np.column_stack([body, rel[:, 2]])
        seen = np.flatnonzero((np.linalg.norm(body[:, :2], axis=1) < 3.0) & (body[:, 0] > 0.2))
        points = body[seen] + rng.normal(scale=0.03, size=(len(seen), 3))
        results = backend.add_landmarks(LandmarkObservations(0, k * DT, points))
        for true_id, r in zip(seen, results, strict=True):
            if r.landmark >= 0:
                labels.append(int(true_id))
                estimates.append(r.landmark)
        if k % 10 == 0:
            backend.update()
    backend.update()
    precision, recall = pairwise_precision_recall(np.array(labels), np.array(estimates))
    assert precision >= 0.95, (precision, recall)
    assert recall >= 0.5, (precision, recall)
    lms = backend.landmarks()
    nearest = np.linalg.norm(lms[:, None, :2] - truth_lms[None, :, :2], axis=2).argmin(axis=1)
    assert len(set(nearest.tolist())) >= 0.9 * len(truth_lms)  # twins stay two landmarks


def _still(backend: SlamBackend, robot: int, stamp: float, turn_rad: float = 0.0) -> None:
    backend.add_odometry(OdometryIncrement(robot, stamp, stamp - DT, 0.0, 0.0, turn_rad))


def test_an_unmapped_landmark_beside_a_mapped_one_never_becomes_it() -> None:
    """A robot maps landmark A, then sees only B, 0.27 m beside A, and starts B as a
    tentative (beyond the new-landmark gate of A). A turn on the spot then makes its
    heading uncertain enough that B falls inside A's gate. No point of B may become A:
    A is older than B's tentative, so the two compete and the point is ambiguous."""
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    mapped, unmapped = np.array([[2.0, 0.0, 0.5]]), np.array([[2.0, 0.27, 0.5]])
    stamp = 0.0
    for _ in range(3):
        stamp += DT
        _still(backend, 0, stamp)
        backend.add_landmarks(LandmarkObservations(0, stamp, mapped))
    backend.update()
    stamp += DT
    _still(backend, 0, stamp)
    assert backend.add_landmarks(LandmarkObservations(0, stamp, unmapped))[0].tentative
    for _ in range(40):  # one turn, in 40 steps
        stamp += DT
        _still(backend, 0, stamp, 2 * math.pi / 40)
    backend.update()
    heading_sigma_rad = math.sqrt(backend.pose_covariance(backend.robot(0))[2, 2])
    # Sideways at 2 m the heading's doubt now exceeds B's distance from A / sqrt(gate).
    assert 2.0 * heading_sigma_rad > 0.27 / math.sqrt(SlamConfig().association_mahalanobis_gate)
    for _ in range(6):
        stamp += DT
        _still(backend, 0, stamp)
        result = backend.add_landmarks(LandmarkObservations(0, stamp, unmapped))[0]
        assert result.landmark != 0 and 0 not in result.probabilities
        backend.update()
    assert np.allclose(backend.landmarks(), mapped, atol=1e-6)  # A was never pulled


def test_a_tentative_gives_way_to_a_landmark_confirmed_after_it() -> None:
    """Robot 0 starts a tentative landmark; robot 1 then confirms a landmark at the same
    place. Robot 0's next points of it go to the confirmed landmark (the tentative is its
    duplicate), not into a second landmark."""
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3), 1: np.array([4.0, 0.0, math.pi])})
    stamp = DT
    for robot in (0, 1):
        _still(backend, robot, stamp)
    assert backend.add_landmarks(LandmarkObservations(0, stamp, np.array([[2.0, 0.0, 0.5]])))[
        0
    ].tentative
    for _ in range(3):
        stamp += DT
        for robot in (0, 1):
            _still(backend, robot, stamp)
        backend.add_landmarks(LandmarkObservations(1, stamp, np.array([[2.0, 0.0, 0.5]])))
    backend.update()
    assert len(backend.landmarks()) == 1
    stamp += DT
    _still(backend, 0, stamp)
    result = backend.add_landmarks(LandmarkObservations(0, stamp, np.array([[2.0, 0.0, 0.5]])))
    assert result[0].landmark == 0 and result[0].probabilities == {0: 1.0}


def test_scan_constraint_overrides_biased_odometry() -> None:
    """Odometry says 1.0 m; a tight scan match between the keyframes' scans says 1.1 m
    (with the second scan taken 0.05 m after its keyframe): the keyframe moves to 1.1."""
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    empty = LidarScan(0, 0.0, np.zeros(1), np.zeros(1), 8.0)
    first = backend.add_scan(empty)
    backend.add_odometry(OdometryIncrement(0, 1.0, 0.0, 1.0, 0.0, 0.0))
    backend.add_odometry(OdometryIncrement(0, 1.1, 1.0, 0.05, 0.0, 0.0))
    second = backend.add_scan(LidarScan(0, 1.1, np.zeros(1), np.zeros(1), 8.0))
    assert backend.scans.keyframe(first) == (0, 0)
    assert backend.scans.keyframe(second) == (0, 1)
    backend.scans.add_constraint(
        first, second, np.array([1.15, 0.0, 0.0]), np.diag([1e-6, 1e-6, 1e-6]), robust=False
    )
    backend.update(extra_iterations=2)
    _, poses = backend.trajectory(0)
    # kf_1 = scan_0 * 1.15 m * (0.05 m offset)^-1 = 1.10 m; odometry (1.0 m) is much looser.
    assert poses[1, 0] == pytest.approx(1.1, abs=2e-3)
    assert backend.scans.pose(second)[0] == pytest.approx(1.15, abs=2e-3)


def test_scans_of_one_keyframe_are_placed_relative_to_each_other_by_their_offsets() -> None:
    """Two scans after one keyframe (0.3 m and 0.5 m of odometry, a 0.2 rad turn between):
    the second's pose in the first's frame, whatever the keyframe's estimate; scans of two
    keyframes have no such pose."""
    backend = SlamBackend(SlamConfig(keyframe_distance_m=1.0), {0: np.array([2.0, 1.0, 0.7])})
    empty = LidarScan(0, 0.0, np.zeros(1), np.zeros(1), 8.0)
    backend.add_odometry(OdometryIncrement(0, 0.5, 0.0, 0.3, 0.0, 0.0))
    first = backend.add_scan(replace(empty, stamp=0.5))
    backend.add_odometry(OdometryIncrement(0, 1.0, 0.5, 0.2, 0.0, 0.2))
    second = backend.add_scan(replace(empty, stamp=1.0))
    backend.add_odometry(OdometryIncrement(0, 2.0, 1.0, 0.9, 0.0, 0.0))
    third = backend.add_scan(replace(empty, stamp=2.0))
    assert backend.scans.keyframe(first) == backend.scans.keyframe(second) == (0, 0)
    assert backend.scans.keyframe(third) == (0, 1)
    backend.update()
    relative = backend.scans.relative(first, second)
    np.testing.assert_allclose(relative, [0.2, 0.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(
        relative, between(backend.scans.pose(first), backend.scans.pose(second)), atol=1e-12
    )
    with pytest.raises(ValueError, match="different keyframes"):
        backend.scans.relative(first, third)


def test_isam2_speed_measurement_is_consistent() -> None:
    """The benchmark's measuring function on a short run: one update per cycle of three
    keyframes, buckets that cover the run, and an estimate that stayed near the truth
    (measured 0.12 m worst final error after 30 cycles, 9 m per robot, before the first
    loop closes; 0.04 m after 100 cycles)."""
    from acslam.benchmarks.isam2 import measure_isam2_updates

    result = measure_isam2_updates(keyframes=90, robots=3, seed=1)
    assert [b["updates"] for b in result["buckets"]] == [30]
    assert result["per_keyframe_mean_ms"] == pytest.approx(result["mean_ms"] / 3)
    bucket = result["buckets"][0]
    assert bucket["per_keyframe_p95_ms"] == pytest.approx(bucket["p95_ms"] / 3)
    assert bucket["association_mean_ms"] > 0 and bucket["association_p95_ms"] > 0
    assert 0 < result["mean_ms"] <= result["buckets"][0]["max_ms"]
    assert result["landmarks"] > 10
    assert result["final_position_error_m"] < 0.2


def test_moved_keyframes_are_measured_from_their_last_report() -> None:
    """A keyframe creeping 3 cm per update past a 5 cm threshold is reported once its
    total move since the last report exceeds 5 cm, not never (as per-update deltas would)."""
    backend = SlamBackend(SlamConfig(correction_threshold_m=0.05), {0: np.zeros(3)})
    pose_keys = np.array([keys.pose_key(0, 1), keys.pose_key(0, 2)], dtype=np.uint64)
    creep = [[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.06, 0.0, 0.0], [0.09, 0.0, 0.0]]
    reports = [backend._report_moves(pose_keys, np.array([p, [5.0, 0.0, 0.0]])) for p in creep]
    assert reports == [[], [], [(0, 1)], []]
    # A keyframe first seen in a later update is reported from its first position on.
    three = np.append(pose_keys, np.uint64(keys.pose_key(0, 3)))
    positions = np.array([[0.09, 0.0, 0.0], [5.0, 0.0, 0.0], [7.0, 0.0, 0.0]])
    assert backend._report_moves(three, positions) == []
    positions[2, 1] = 0.06
    assert backend._report_moves(three, positions) == [(0, 3)]


def test_descriptors_keep_a_different_looking_point_off_a_landmark() -> None:
    """Two points at the same place: with the landmark's own descriptor the second frame's
    point is that landmark; with a descriptor 128 of 256 bits away it may not be (the
    Hamming gate is 64 bits), so it starts a landmark of its own."""
    rng = np.random.default_rng(5)
    seen = rng.integers(0, 256, (1, 32), dtype=np.uint8)
    other = seen.copy()
    other[0, :16] ^= 0xFF  # 16 bytes x 8 bits = 128 bits differ
    point = np.array([[1.5, 0.2, 0.3]])
    backend = SlamBackend(SlamConfig(landmark_confirmations=1), {0: np.zeros(3)})
    (first,) = backend.add_landmarks(LandmarkObservations(0, 0.1, point, descriptors=seen))
    backend.update()
    (same,) = backend.add_landmarks(LandmarkObservations(0, 0.2, point, descriptors=seen))
    (different,) = backend.add_landmarks(LandmarkObservations(0, 0.3, point, descriptors=other))
    (plain,) = backend.add_landmarks(LandmarkObservations(0, 0.4, point))
    assert first.is_new and first.landmark == 0
    assert (same.landmark, same.is_new) == (0, False)
    assert different.is_new and different.landmark == 1
    # Without descriptors geometry alone decides: two landmarks in the gate, ambiguous.
    assert plain.landmark == -1 and not plain.is_new


def test_landmark_factors_are_linearized_without_copying_the_graph(monkeypatch) -> None:
    """iSAM2 hands every CustomFactor its whole linearization point; the back end keeps a
    Python view of it so that pybind11 passes that view instead of a fresh copy of every
    value in the graph (what made each landmark factor cost O(trajectory))."""
    from acslam.slam import factors

    seen: list[object] = []
    error = factors._observation_error

    def spy(measured, this, values, jacobians):
        seen.append(values)
        return error(measured, this, values, jacobians)

    monkeypatch.setattr(factors, "_observation_error", spy)
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3)})
    _feed(backend, {0: _circle_truth(np.zeros(3), 0.3, 0.15, 40)}, None)
    assert len(seen) > 20
    assert all(values is backend._linearization_point for values in seen)


def test_reused_relative_covariances_are_never_narrower_than_the_joint_marginal(
    monkeypatch,
) -> None:
    """Frames whose landmarks' covariance relative to a recent keyframe is reused (plus the
    odometry chain since) instead of a joint marginal, with a reused pose marginal as well
    (:meth:`SlamBackend._keyframe_marginal`), and landmarks without a factor for more than
    ``association_joint_marginal_max_age_updates`` updates scored with their last known
    marginal and no cross term: on the seeded three-robot benchmark run, every such
    squared Mahalanobis distance is at most the exact one (the covariances used are the
    wider: they leave out what the graph learnt since), the gating decisions are the
    exact ones for >= 99 % of the pairs (measured 99.7 %) and the 5-sigma
    new-landmark decisions for all, and only the landmarks no keyframe of the last five
    related to the robot and seen in the last ten updates enter a joint marginal (here 30 %
    of the landmark columns scored; those coming back into view after a lap, 6.7 %, do
    not)."""
    from acslam.benchmarks.isam2 import measure_isam2_updates
    from acslam.slam import landmark_association
    from acslam.slam.association import innovation_covariance, mahalanobis_sq
    from acslam.slam.association import pose_lever_jacobian as lever_of
    from acslam.slam.factors import point_to_body, rotation_about_z

    pairs: list[tuple[float, float]] = []
    columns_scored = columns_queried = columns_stale = 0
    max_age = SlamConfig().association_joint_marginal_max_age_updates
    score = landmark_association.LandmarkAssociation._score_frame
    blocks = SlamBackend.landmark_blocks

    def counted_blocks(self, ref_key, columns):
        nonlocal columns_queried
        columns_queried += len(columns) if ref_key is not None else 0
        association = self.association
        ages = [self.update_count - association._last_factor_update[i] for i in columns]
        assert all(age <= max_age for age in ages)
        return blocks(self, ref_key, columns)

    def exact_too(self, robot, frame):
        nonlocal columns_scored, columns_stale
        scores = score(self, robot, frame)
        if not scores.confirmed:
            return scores
        columns_scored += len(scores.confirmed)
        updates = self.backend.update_count
        ages = [updates - self._last_factor_update[i] for i in scores.confirmed]
        columns_stale += sum(age > max_age for age in ages)
        reused_pose, robot.pose_marginal = robot.pose_marginal, None  # a fresh marginal
        ref_key, ref_pose, ref_cov = self.backend.reference(robot)
        robot.pose_marginal = reused_pose
        _, lm_covs, cross = blocks(self.backend, ref_key, scores.confirmed)
        rotation = rotation_about_z(ref_pose.theta())
        for n, point in enumerate(frame.world):
            lever = lever_of(rotation, point_to_body(ref_pose, point)[0])
            for c, i in enumerate(scores.confirmed):
                if np.isfinite(scores.d2[n, c]):
                    s = innovation_covariance(lever, ref_cov, lm_covs[c], cross[c], frame.sensor[n])
                    innovation = point - self.backend.landmark_positions[i]
                    pairs.append((scores.d2[n, c], mahalanobis_sq(innovation, s)))
        return scores

    monkeypatch.setattr(SlamBackend, "landmark_blocks", counted_blocks)
    monkeypatch.setattr(landmark_association.LandmarkAssociation, "_score_frame", exact_too)
    measure_isam2_updates(keyframes=300, robots=3, seed=0)
    reused, exact = np.array(pairs).T
    gate = SlamConfig().association_mahalanobis_gate
    assert len(pairs) > 500
    assert np.all(reused <= exact * (1 + 1e-9))
    assert np.mean((reused <= gate) == (exact <= gate)) >= 0.99
    assert np.array_equal(reused < 25.0, exact < 25.0)
    assert columns_queried < 0.4 * columns_scored
    assert columns_stale > 0.05 * columns_scored


@pytest.mark.parametrize("reuse", [0, 5])
def test_pose_marginal_reused_for_a_few_keyframes_is_never_narrower(monkeypatch, reuse) -> None:
    """On the noisy three-robot run, every pose covariance association gets is the robot's
    last computed keyframe marginal carried along the odometry chain since, while that is
    fewer than ``association_covariance_reuse_keyframes`` keyframes back, else iSAM2's
    fresh marginal; and it is never narrower than the fresh one, up to the first order
    of the propagation. With 0 every covariance is the fresh marginal."""
    calls: list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]] = []
    keyframe_marginal = SlamBackend._keyframe_marginal

    def recorded(self, robot, index):
        cached = robot.pose_marginal
        got = keyframe_marginal(self, robot, index)
        fresh = self._marginal(robot.pose_keys[index])
        reused = cached is not None and 0 <= index - cached[0] < reuse
        expected = fresh
        if reused:
            since, expected = cached
            for k in range(since + 1, index + 1):
                a, b = (self.pose_estimate(robot.pose_keys[j]) for j in (k - 1, k))
                # Pose k = pose k-1 * relative: a body-frame error e of k-1 is
                # Ad(relative^-1) e at k (checked against GTSAM's own Jacobian).
                jacobian = np.zeros((3, 3), order="F")
                a.between(b, jacobian, np.zeros((3, 3), order="F"))
                odometry = np.diag(self._odometry_variances[robot.pose_keys[k]])
                expected = jacobian @ expected @ jacobian.T + odometry
        calls.append((got, expected, fresh, reused))
        return got

    monkeypatch.setattr(SlamBackend, "_keyframe_marginal", recorded)
    team = _team()
    config = SlamConfig(association_covariance_reuse_keyframes=reuse)
    backend = SlamBackend(config, {r: t[0] for r, t in team.items()})
    _feed(backend, team, np.random.default_rng(4), odom_sigma=0.003, point_sigma=0.02)
    reused_count = sum(reused for *_, reused in calls)
    assert len(calls) > 200
    assert reused_count > 0.5 * len(calls) if reuse else reused_count == 0
    for got, expected, fresh, _ in calls:
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
        # got >= fresh to first order: no direction narrower by more than the estimate's
        # moves since the reused marginal allow (measured: none, to rounding).
        assert scipy.linalg.eigh(got, fresh, eigvals_only=True).min() >= 0.995


def test_a_start_placed_by_a_merge_is_held_as_loosely_as_its_sigmas() -> None:
    """Alone in the graph, a start's marginal is its prior: the config's for a known
    start, the given sigmas for one a merge of frames placed."""
    sigmas = np.array([0.1, 0.1, 0.02])
    backend = SlamBackend(SlamConfig(), {0: np.zeros(3), 1: np.array([2.0, 1.0, 0.5])}, {1: sigmas})
    backend.update()
    known = backend.pose_covariance(backend.robot(0))
    placed = backend.pose_covariance(backend.robot(1))
    config = SlamConfig()
    np.testing.assert_allclose(
        np.sqrt(np.diag(known)),
        [config.prior_sigma_xy_m, config.prior_sigma_xy_m, config.prior_sigma_theta_rad],
        rtol=1e-6,
    )
    np.testing.assert_allclose(np.sqrt(np.diag(placed)), sigmas, rtol=1e-6)
