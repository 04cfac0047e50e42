"""Landmark observations into the team's graph: joint association of each frame's points,
tentative landmarks, known identities, and robot-to-robot sightings.

The points of one frame are associated jointly (:mod:`acslam.slam.association`); see
:class:`~acslam.config.SlamConfig` for the gates. A new landmark is tentative until the
same robot sees it in ``landmark_confirmations`` frames; its observations wait outside the
graph until then.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from acslam.errors import SlamError
from acslam.messages import LandmarkObservations
from acslam.pipeline.stages import AssociationResult
from acslam.slam import keys
from acslam.slam.association import (
    assign_frame,
    euclidean_gate,
    exclusive_probabilities,
    innovation_covariance,
    mahalanobis_sq,
    measurement_covariance,
    pose_lever_jacobian,
)
from acslam.slam.factors import (
    observation_factor,
    observation_noise,
    point_to_body,
    point_to_world,
    robot_observation_factor,
    rotation_about_z,
    sensor_covariance,
)

if TYPE_CHECKING:
    import gtsam

    from acslam.config import SlamConfig
    from acslam.slam.backend import SlamBackend, _Robot


@dataclass
class _Tentative:
    """A landmark seen but not yet confirmed: its observations wait outside the graph.

    ``landmarks_before``: how many landmarks the graph held when it was started. Those
    were judged distinct from it then (its first point was beyond the new-landmark gate
    of each one the rest of its frame left free); only a later one may be its duplicate."""

    robot_id: int
    observations: list[tuple[int, np.ndarray, np.ndarray]]  # (pose key, z_kf, cov_kf)
    kf_index: int
    stamp: float
    landmarks_before: int
    descriptor: np.ndarray | None = None


@dataclass
class _Frame:
    """One frame's points: z in the latest keyframe (``kf``, with ``cov_kf``), z in the
    world, and the world covariance of T z from the sensor alone and with the pose
    marginal (``cov``)."""

    pose_key: int
    descriptors: np.ndarray | None = None
    kf: list[np.ndarray] = field(default_factory=list)
    cov_kf: list[np.ndarray] = field(default_factory=list)
    world: list[np.ndarray] = field(default_factory=list)
    sensor: list[np.ndarray] = field(default_factory=list)
    cov: list[np.ndarray] = field(default_factory=list)


@dataclass(frozen=True)
class _Relative:
    """A landmark's covariance in the frame of one of a robot's keyframes, from an iSAM2
    joint marginal, for that robot's next frames."""

    kf_index: int
    pose_key: int
    covariance: np.ndarray  # 3x3, in the keyframe's body frame


@dataclass
class _Scores:
    """Squared Mahalanobis distances and Gaussian log-normalisers, points x columns
    (confirmed landmarks, then this robot's tentatives)."""

    d2: np.ndarray
    log_norm: np.ndarray
    confirmed: list[int]
    tentatives: list[_Tentative]


def to_keyframe(
    config: SlamConfig, robot: _Robot, point: np.ndarray, offset_cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A point seen now -> the robot's latest keyframe frame, with its covariance: the
    sensor's, rotated by the offset's heading, plus the offset's odometry uncertainty."""
    offset = robot.offset
    offset_rot = rotation_about_z(offset[2])
    rotated = offset_rot @ point
    point_kf = rotated + np.array([offset[0], offset[1], 0.0])
    jac_offset = np.array([[1.0, 0.0, -rotated[1]], [0.0, 1.0, rotated[0]], [0.0, 0.0, 0.0]])
    sensor_cov = sensor_covariance(config, point)
    cov_kf = offset_rot @ sensor_cov @ offset_rot.T + jac_offset @ offset_cov @ jac_offset.T
    return point_kf, cov_kf


def hamming_bits(a: np.ndarray, b: np.ndarray) -> int:
    """Bits in which two binary descriptors (uint8 rows) differ. A point may be a
    landmark only if both look alike, when both carry descriptors."""
    return int(np.unpackbits(np.bitwise_xor(a, b)).sum())


def alike(
    config: SlamConfig,
    frame: _Frame,
    n: int,
    candidates: Sequence[int],
    descriptors: dict[int, np.ndarray | None],
) -> list[int]:
    """The candidates point ``n`` of ``frame`` may be by its descriptor: those without one,
    and of those with one, the ones within the Hamming gate and within the margin of the
    best (a ratio test: a descriptor much closer than the rest decides)."""
    if frame.descriptors is None:
        return [int(i) for i in candidates]
    bits = {
        int(i): hamming_bits(frame.descriptors[n], descriptors[int(i)])
        for i in candidates
        if descriptors.get(int(i)) is not None
    }
    limit = config.association_max_descriptor_bits
    if bits:
        limit = min(limit, min(bits.values()) + config.association_descriptor_margin_bits)
    return [int(i) for i in candidates if bits.get(int(i), -1) <= limit]


def gate_radius(config: SlamConfig, point_cov: np.ndarray) -> float:
    """Euclidean pre-gate of a point: ``association_gate_m``, widened to the Mahalanobis
    gate of the point's own world covariance (pose marginal included) so that a robot
    whose estimate drifted further than the fixed gate can still find its landmarks."""
    widest = float(np.linalg.eigvalsh(point_cov)[-1])
    return max(
        config.association_gate_m, float(np.sqrt(config.association_mahalanobis_gate * widest))
    )


def chain_variance(robot: _Robot, since: int, now: int, lever_sq: float) -> float:
    """Planar position variance the odometry chain from keyframe ``since`` to ``now`` adds
    to a point seen at squared range ``lever_sq`` (heading error x lever arm)."""
    var_xy = robot.cum_var_xy[now] - robot.cum_var_xy[since]
    var_th = robot.cum_var_theta[now] - robot.cum_var_theta[since]
    length = robot.cum_distance_m[now] - robot.cum_distance_m[since]
    return var_xy + var_th * (length**2 + lever_sq)


class LandmarkAssociation:
    """Adds a :class:`~acslam.slam.backend.SlamBackend`'s landmark and sighting factors."""

    def __init__(self, backend: SlamBackend) -> None:
        self.backend = backend
        self.config = backend.config
        self._known_landmarks: dict[int, int] = {}
        self._descriptors: dict[int, np.ndarray] = {}  # landmark -> its first descriptor
        self._tentatives: list[_Tentative] = []
        self._relative: dict[tuple[int, int], _Relative] = {}  # by (robot, landmark)
        self._last_factor_update: dict[int, int] = {}  # landmark -> backend.update_count
        self.robot_observations = 0
        self.dropped_ambiguous = 0
        self.tentative_observations = 0
        self.expired_tentatives = 0

    # ------------------------------------------------------------------ landmarks

    def add_landmarks(self, msg: LandmarkObservations) -> list[AssociationResult]:
        """Associate the frame's points jointly and add their factors; points that carry
        identities (``msg.ids``) skip association and are used as identified."""
        backend = self.backend
        robot = backend.accept("landmarks", msg.robot_id, msg.stamp)
        if robot is None or len(msg.points) == 0:
            return []
        points = np.asarray(msg.points, dtype=float).reshape(-1, 3)
        finite = np.isfinite(points).all(axis=1)
        if not finite.all():  # non-finite points are skipped (counted), the rest are used
            skipped = backend.skipped_messages
            skipped["landmark_points"] = skipped.get("landmark_points", 0) + int((~finite).sum())
        results = [AssociationResult(-1, False, {}) for _ in points]
        if not finite.any():
            return results
        descriptors = None if msg.descriptors is None else msg.descriptors[finite]
        frame = self._frame(robot, points[finite], descriptors)
        if msg.ids is not None:
            used = self._add_known(frame, [int(k) for k in msg.ids[finite]])
        else:
            used = self._associate_frame(robot, msg.stamp, frame)
        for i, result in zip(np.flatnonzero(finite), used, strict=True):
            results[i] = result
        return results

    def _frame(self, robot: _Robot, points: np.ndarray, descriptors: np.ndarray | None) -> _Frame:
        backend = self.backend
        pose_key = robot.pose_keys[-1]
        pose = backend.pose_estimate(pose_key)
        rotation = rotation_about_z(pose.theta())
        pose_cov = backend.pose_covariance(robot)
        offset_cov = backend.offset_covariance(robot)
        frame = _Frame(pose_key, descriptors)
        for point in points:
            point_kf, cov_kf = to_keyframe(self.config, robot, point, offset_cov)
            frame.kf.append(point_kf)
            frame.cov_kf.append(cov_kf)
            frame.world.append(point_to_world(pose, point_kf))
            frame.sensor.append(rotation @ cov_kf @ rotation.T)
            frame.cov.append(measurement_covariance(rotation, point_kf, cov_kf, pose_cov))
        return frame

    def _add_factor(self, pose_key: int, index: int, point_kf, cov_kf, probability: float) -> None:
        noise = observation_noise(cov_kf, probability, self.config.huber_k)
        factor = observation_factor(pose_key, keys.landmark_key(index), point_kf, noise)
        self.backend.add_factor(factor)
        self._last_factor_update[index] = self.backend.update_count

    def _new_landmark(self, frame: _Frame, n: int) -> int:
        index = self.backend.new_landmark(frame.world[n], frame.cov[n])
        if frame.descriptors is not None:
            self._descriptors[index] = frame.descriptors[n]
        return index

    def _add_known(self, frame: _Frame, known_ids: list[int]) -> list[AssociationResult]:
        results = []
        for n, known in enumerate(known_ids):
            index = self._known_landmarks.get(int(known))
            is_new = index is None
            if is_new:
                index = self._new_landmark(frame, n)
                self._known_landmarks[int(known)] = index
            self._add_factor(frame.pose_key, index, frame.kf[n], frame.cov_kf[n], 1.0)
            results.append(AssociationResult(index, is_new, {index: 1.0}))
        return results

    # ------------------------------------------------------------------ joint association

    def _associate_frame(
        self, robot: _Robot, stamp: float, frame: _Frame
    ) -> list[AssociationResult]:
        """Joint association of one frame (see :mod:`acslam.slam.association`).

        Columns are the confirmed landmarks within the Euclidean pre-gate of some point and
        this robot's live tentative landmarks. Innovation covariances use the pose-landmark
        cross-covariance from an iSAM2 joint marginal for confirmed landmarks (or, within
        ``association_covariance_reuse_keyframes`` of this robot's last one, the landmark's
        covariance relative to that keyframe plus the odometry chain since; or, for a
        landmark without a factor in ``association_joint_marginal_max_age_updates``
        updates, its last known marginal beside the pose's, without the cross term), and for
        a tentative one the odometry chain between the keyframe it was last seen from and now.
        """
        self._expire_tentatives(robot.robot_id, stamp)
        scores = self._score_frame(robot, frame)
        assigned = assign_frame(scores.d2, self.config.association_mahalanobis_gate)
        results: list[AssociationResult] = []
        new_points: list[int] = []
        for n in range(len(frame.world)):
            others = np.zeros(scores.d2.shape[1], dtype=bool)
            for m in range(len(frame.world)):
                if m != n and assigned[m] >= 0:
                    others[assigned[m]] = True
            result = self._decide(robot, stamp, frame, scores, n, int(assigned[n]), others)
            if result is None:
                new_points.append(n)
                result = AssociationResult(-1, True, {}, tentative=True)
            results.append(result)
        for n in new_points:
            descriptor = None if frame.descriptors is None else frame.descriptors[n]
            tentative = _Tentative(
                robot.robot_id, [], len(robot.pose_keys) - 1, stamp,
                len(self.backend.landmark_positions), descriptor,
            )  # fmt: skip
            self._tentatives.append(tentative)
            results[n] = self._observe_tentative(robot, stamp, tentative, frame, n)
        return results

    def _score_frame(self, robot: _Robot, frame: _Frame) -> _Scores:
        backend = self.backend
        world = np.array(frame.world)
        positions = backend.landmark_positions
        per_point = [
            euclidean_gate(p, positions, gate_radius(self.config, cov))
            for p, cov in zip(world, frame.cov, strict=True)
        ]
        confirmed = sorted({int(i) for g in per_point for i in g})
        tentatives = [t for t in self._tentatives if t.robot_id == robot.robot_id]
        n_cols = len(confirmed) + len(tentatives)
        scores = _Scores(
            np.full((len(world), n_cols), np.inf), np.zeros((len(world), n_cols)), confirmed,
            tentatives,
        )  # fmt: skip
        if not n_cols:
            return scores
        ref_key, ref_pose, ref_cov = backend.reference(robot)
        ref_rot = rotation_about_z(ref_pose.theta())
        now_index = len(robot.pose_keys) - 1
        reused = self._reusable(robot.robot_id, confirmed, now_index)
        max_age_updates = self.config.association_joint_marginal_max_age_updates
        stale = {
            i
            for i in confirmed
            if i not in reused
            and backend.update_count - self._last_factor_update[i] > max_age_updates
        }
        queried = [i for i in confirmed if i not in reused and i not in stale]
        pose_block, lm_covs, cross = backend.landmark_blocks(ref_key, queried)
        if pose_block is not None:
            self._remember(robot.robot_id, ref_key, ref_pose, pose_block, queried, lm_covs, cross)
        query_of = {i: q for q, i in enumerate(queried)}
        col_of = {i: c for c, i in enumerate(confirmed)}
        tent_geometry = []
        for t in tentatives:
            key, z_kf, cov_kf = t.observations[-1]
            pose = backend.pose_estimate(key)
            rot = rotation_about_z(pose.theta())
            tent_geometry.append((point_to_world(pose, z_kf), rot @ cov_kf @ rot.T))
        for n in range(len(world)):
            lever = pose_lever_jacobian(ref_rot, point_to_body(ref_pose, world[n])[0])
            rho2 = float(frame.kf[n][:2] @ frame.kf[n][:2])
            for i in alike(self.config, frame, n, per_point[n], self._descriptors):
                if i in reused:
                    since, relative = reused[i]
                    chain = chain_variance(robot, since, now_index, rho2)
                    s = relative + np.diag([chain, chain, 0.0]) + frame.sensor[n]
                elif i in stale:
                    last = backend.last_landmark_covariance(i)
                    s = innovation_covariance(lever, ref_cov, last, None, frame.sensor[n])
                else:
                    q = query_of[i]
                    s = innovation_covariance(lever, ref_cov, lm_covs[q], cross[q], frame.sensor[n])
                self._score(scores, n, col_of[i], world[n] - positions[i], s)
            for k, (position, cov) in enumerate(tent_geometry):
                innovation = world[n] - position
                if np.linalg.norm(innovation) > self.config.association_gate_m:
                    continue
                if not alike(self.config, frame, n, [0], {0: tentatives[k].descriptor}):
                    continue
                chain = chain_variance(robot, tentatives[k].kf_index, now_index, rho2)
                s = frame.sensor[n] + cov + np.diag([chain, chain, 0.0])
                self._score(scores, n, len(confirmed) + k, innovation, s)
        return scores

    def _reusable(
        self, robot_id: int, landmarks: list[int], now_index: int
    ) -> dict[int, tuple[int, np.ndarray]]:
        """Landmarks whose covariance relative to one of this robot's keyframes is recent
        enough to reuse: keyframe index and that covariance in the world frame (rotated by
        the keyframe's current estimate).

        The innovation covariance of a re-observed landmark is its uncertainty relative
        to the robot; from a keyframe a few steps back, the odometry chain since then adds
        to it (as for tentatives, :func:`chain_variance`). That leaves out what the graph
        learnt since, so it errs on the wide side, and it saves the joint marginal, whose
        cost grows with the graph, in most frames.
        """
        reuse = self.config.association_covariance_reuse_keyframes
        found: dict[int, tuple[int, np.ndarray]] = {}
        for i in landmarks:
            relative = self._relative.get((robot_id, i))
            if relative is None or now_index - relative.kf_index >= reuse:
                continue
            rotation = rotation_about_z(self.backend.pose_estimate(relative.pose_key).theta())
            found[i] = (relative.kf_index, rotation @ relative.covariance @ rotation.T)
        return found

    def _remember(
        self,
        robot_id: int,
        ref_key: int,
        ref_pose: gtsam.Pose2,
        pose_block: np.ndarray,
        landmarks: list[int],
        lm_covs: list[np.ndarray],
        cross: list[np.ndarray | None],
    ) -> None:
        """Keep each landmark's covariance in the frame of the reference keyframe, from the
        joint marginal of both: J [[P, C], [C^T, L]] J^T with J the Jacobians of the
        point in the keyframe's frame (:func:`point_to_body`)."""
        kf_index = keys.decode_pose_key(ref_key)[1]
        positions = self.backend.landmark_positions
        for i, lm_cov, pose_lm in zip(landmarks, lm_covs, cross, strict=True):
            if pose_lm is None:
                continue
            _, h_pose, h_point = point_to_body(ref_pose, positions[i])
            jac = np.hstack([h_pose, h_point])
            cov = jac @ np.block([[pose_block, pose_lm], [pose_lm.T, lm_cov]]) @ jac.T
            self._relative[(robot_id, i)] = _Relative(kf_index, ref_key, 0.5 * (cov + cov.T))

    def _decide(
        self,
        robot: _Robot,
        stamp: float,
        frame: _Frame,
        scores: _Scores,
        n: int,
        column: int,
        others: np.ndarray,
    ) -> AssociationResult | None:
        """What point ``n``, assigned ``column`` (-1: none), becomes; None: a new landmark.
        ``others`` marks the columns other points of the frame took."""
        cfg = self.config
        gate = cfg.association_mahalanobis_gate
        d2, log_norm, confirmed = scores.d2, scores.log_norm, scores.confirmed
        if column < 0:
            near = d2[n] < cfg.new_landmark_mahalanobis_gate
            if (near & ~others).any():
                self.dropped_ambiguous += 1
                return AssociationResult(-1, False, {})
            return None
        # A confirmed landmark in the gate takes precedence over a tentative it may
        # duplicate: one confirmed after the tentative was started (seen by this robot
        # before another robot's observations confirmed it). Letting the two split the
        # probability would drop every point until the tentative expires. An older
        # landmark was judged distinct from the tentative when it started, so the two
        # compete: an unmapped landmark a few decimetres from a mapped one, seen by a
        # robot whose pose is uncertain, must not become the mapped one (on office_b,
        # such a factor moved a robot's estimate half a metre, and it drove into a wall).
        excluded = others.copy()
        n_conf = len(confirmed)
        row = np.where(others[:n_conf], np.inf, d2[n, :n_conf])
        if column >= n_conf and n_conf:
            newer = np.array(confirmed) >= scores.tentatives[column - n_conf].landmarks_before
            row = np.where(newer, row, np.inf)
            if row.min() <= gate:
                column = int(np.argmin(row))
        if column < n_conf:
            excluded[n_conf:] = True
        cols, probs = exclusive_probabilities(
            d2[n], log_norm[n], gate, excluded, cfg.association_min_likelihood
        )
        best = float(probs[cols == column][0])
        if best < cfg.association_min_best_probability:
            self.dropped_ambiguous += 1
            return AssociationResult(-1, False, {})
        if column >= n_conf:
            tentative = scores.tentatives[column - n_conf]
            return self._observe_tentative(robot, stamp, tentative, frame, n)
        soft = {
            confirmed[c]: float(p)
            for c, p in zip(cols, probs, strict=True)
            if c < n_conf and p >= cfg.association_min_probability
        }
        total = sum(soft.values())
        soft = {i: p / total for i, p in soft.items()}
        for index, probability in soft.items():
            self._add_factor(frame.pose_key, index, frame.kf[n], frame.cov_kf[n], probability)
        return AssociationResult(confirmed[column], False, soft)

    @staticmethod
    def _score(scores: _Scores, n: int, c: int, innovation: np.ndarray, s: np.ndarray) -> None:
        scores.d2[n, c] = mahalanobis_sq(innovation, s)
        if np.isfinite(scores.d2[n, c]):
            scores.log_norm[n, c] = 0.5 * (3 * np.log(2 * np.pi) + np.linalg.slogdet(s)[1])

    # ------------------------------------------------------------------ tentatives

    def _observe_tentative(
        self, robot: _Robot, stamp: float, tentative: _Tentative, frame: _Frame, n: int
    ) -> AssociationResult:
        """Buffer an observation of a tentative landmark; confirm it once seen often enough."""
        tentative.observations.append((frame.pose_key, frame.kf[n], frame.cov_kf[n]))
        tentative.kf_index = len(robot.pose_keys) - 1
        tentative.stamp = stamp
        if len(tentative.observations) < self.config.landmark_confirmations:
            self.tentative_observations += 1
            return AssociationResult(-1, True, {}, tentative=True)
        self._tentatives.remove(tentative)
        index = self._new_landmark(frame, n)
        for pose_key, z_kf, cov_kf in tentative.observations:
            self._add_factor(pose_key, index, z_kf, cov_kf, 1.0)
        return AssociationResult(index, True, {index: 1.0})

    def _expire_tentatives(self, robot_id: int, stamp: float) -> None:
        timeout = self.config.tentative_timeout_s
        keep = []
        for t in self._tentatives:
            if t.robot_id == robot_id and stamp - t.stamp > timeout:
                self.expired_tentatives += 1
            else:
                keep.append(t)
        self._tentatives = keep

    # ------------------------------------------------------------------ sightings

    def add_robot_observation(
        self, observer_id: int, observed_id: int, stamp: float, point: np.ndarray
    ) -> bool:
        """Robot ``observed_id`` seen by robot ``observer_id`` at ``point`` (observer frame).

        The observed robot's identity must come from a recognition signal of its own (e.g.
        a marker on it), so no association is needed. The factor ties both robots' latest
        keyframes: the point enters the observer's keyframe frame as a landmark point does,
        and the observed robot stands at the odometry offset since its own keyframe, whose
        uncertainty is added to the covariance. Huber-robust like a landmark observation.
        Returns whether a factor was added (False: skipped as out of order or non-finite).
        """
        backend = self.backend
        if int(observer_id) == int(observed_id):
            raise ValueError(f"robot {observer_id} cannot observe itself")
        observed = backend.robot(observed_id)
        if observed is None:
            raise SlamError(f"observation of robot {observed_id}, which has no start pose")
        point = np.asarray(point, dtype=float).reshape(3)
        robot = backend.accept("robots", observer_id, stamp)
        if robot is None:
            return False
        if not np.isfinite(point).all():
            skipped = backend.skipped_messages
            skipped["robot_points"] = skipped.get("robot_points", 0) + 1
            return False
        point_kf, cov_kf = to_keyframe(self.config, robot, point, backend.offset_covariance(robot))
        target_var = backend.offset_covariance(observed)[0, 0]
        cov_kf = cov_kf + np.diag([target_var, target_var, 0.0])
        noise = observation_noise(cov_kf, 1.0, self.config.huber_k)
        target = np.array([observed.offset[0], observed.offset[1], 0.0])
        backend.add_factor(
            robot_observation_factor(
                robot.pose_keys[-1], observed.pose_keys[-1], point_kf, target, noise
            )
        )
        self.robot_observations += 1
        return True
