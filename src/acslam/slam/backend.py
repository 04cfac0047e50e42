"""Centralized multi-robot SLAM back end: one iSAM2 over all robots' poses and landmarks.

Graph (thesis eqs. 4.17-4.20): a prior on each robot's known start pose, SE(3) odometry
between-factors between consecutive keyframes, and Huber-robust landmark observation
factors, softly associated by PDA (eqs. 4.21-4.24) to landmarks shared by all robots,
and Huber-robust factors between two robots' keyframes when one robot sees another.

Keyframes: a robot gets a new pose variable only when the odometry accumulated since its
last keyframe exceeds ``keyframe_distance_m`` of path or ``keyframe_angle_rad`` of turn,
so the graph grows with distance travelled, not with time. Landmark observations and
LiDAR scans made between keyframes attach to the robot's *latest* keyframe (the nearest
one that exists when they arrive; a later keyframe is not known yet) through the
odometry offset since it: an observation z becomes z_kf = offset * z in the keyframe
frame, with the offset's odometry uncertainty added to its covariance; a scan is stored
with its offset so its world pose follows the keyframe's optimised pose.

Robot ids and timestamps are taken from the messages; a message whose stamp is earlier
than the previous message of the same kind from the same robot is skipped and counted.
GTSAM exceptions never escape: they become :class:`SlamError`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import gtsam
import numpy as np

from acslam.config import SlamConfig
from acslam.errors import SlamError
from acslam.geometry import between, compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement
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
    odometry_noise,
    odometry_sigmas,
    planar_compose_jacobians,
    planar_to_pose3,
    pose3_to_planar,
    prior_noise,
    robot_observation_factor,
    sensor_covariance,
)

_GTSAM_ERRORS = (RuntimeError, ValueError, IndexError, KeyError)
_POSE_CHAR_CODE = ord(keys.POSE_CHAR)


def inverse(pose: np.ndarray) -> np.ndarray:
    """SE(2) inverse of ``[x, y, theta]``."""
    return between(pose, np.zeros(3))


@dataclass(frozen=True)
class AssociationResult:
    """What one observed point became: its most probable landmark and all probabilities.

    ``landmark`` is -1 (and ``probabilities`` empty) for a point that made no factor: an
    ambiguous point that was dropped, or (``tentative`` True) an observation of a
    tentative landmark not confirmed yet (its factor is added if it gets confirmed).
    """

    landmark: int
    is_new: bool
    probabilities: dict[int, float]
    tentative: bool = False


@dataclass
class _Robot:
    robot_id: int
    pose_keys: list[int]
    stamps: list[float]
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance_m: float = 0.0
    angle_rad: float = 0.0
    last_stamp: dict[str, float] = field(default_factory=dict)
    # Per keyframe index: cumulative odometry variance (xy, theta) and path length from
    # the start, for the relative uncertainty between two keyframes of this robot.
    cum_var_xy: list[float] = field(default_factory=lambda: [0.0])
    cum_var_theta: list[float] = field(default_factory=lambda: [0.0])
    cum_distance_m: list[float] = field(default_factory=lambda: [0.0])


@dataclass
class _Tentative:
    """A landmark seen but not yet confirmed: its observations wait outside the graph."""

    robot_id: int
    observations: list[tuple[int, np.ndarray, np.ndarray]]  # (pose key, z_kf, cov_kf)
    kf_index: int
    stamp: float


def _planar_covariance(pose6_cov: np.ndarray, yaw: float) -> np.ndarray:
    """Pose3 body-frame 6x6 marginal -> world-frame ``[x, y, theta]`` 3x3 covariance."""
    body = pose6_cov[np.ix_([3, 4, 2], [3, 4, 2])]
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot @ body @ rot.T


class SlamBackend:
    """One iSAM2 for the whole team. Feed messages, call :meth:`update`, query the estimate."""

    def __init__(self, config: SlamConfig, starts: dict[int, np.ndarray]) -> None:
        if not starts:
            raise ValueError("SlamBackend needs the start pose of at least one robot")
        self.config = config
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(config.isam_relinearize_threshold)
        params.relinearizeSkip = config.isam_relinearize_skip
        params.setFactorization(config.isam_factorization)
        self._isam = gtsam.ISAM2(params)
        self._graph = gtsam.NonlinearFactorGraph()
        self._initial = gtsam.Values()
        self._estimate = gtsam.Values()
        self._robots: dict[int, _Robot] = {}
        self._landmark_positions = np.zeros((0, 3))
        self._pending_landmark_covs: dict[int, np.ndarray] = {}
        self._marginals: dict[int, np.ndarray] = {}
        self._odometry_variances: dict[int, np.ndarray] = {}
        self._known_landmarks: dict[int, int] = {}
        self._scans: list[tuple[LidarScan, int, np.ndarray]] = []
        self._scans_by_keyframe: dict[int, list[int]] = {}
        self._moved: list[tuple[int, int]] = []
        # Per pose key, the position last reported (by moved_keyframes, or when first
        # estimated): users placed the keyframe's scans there.
        self._reported_keys = np.zeros(0, dtype=np.uint64)
        self._reported_positions = np.zeros((0, 3))
        self.skipped_messages: dict[str, int] = {"odometry": 0, "landmarks": 0, "scan": 0}
        self.robot_observations = 0
        self.update_durations_s: list[float] = []
        self.dropped_ambiguous = 0
        self.tentative_observations = 0
        self.expired_tentatives = 0
        self._tentatives: list[_Tentative] = []
        for robot_id, start in starts.items():
            start = np.asarray(start, dtype=float)
            key = keys.pose_key(int(robot_id), 0)
            self._robots[int(robot_id)] = _Robot(int(robot_id), [key], [float("nan")])
            self._graph.add(
                gtsam.PriorFactorPose3(key, planar_to_pose3(start), prior_noise(config))
            )
            self._initial.insert(key, planar_to_pose3(start))

    # ------------------------------------------------------------------ input

    def _accept(self, kind: str, robot_id: int, stamp: float) -> _Robot | None:
        robot = self._robots.get(int(robot_id))
        if robot is None:
            raise SlamError(f"{kind} message from robot {robot_id}, which has no start pose")
        if stamp < robot.last_stamp.get(kind, -np.inf):
            self.skipped_messages[kind] = self.skipped_messages.get(kind, 0) + 1
            return None
        robot.last_stamp[kind] = stamp
        if np.isnan(robot.stamps[0]):
            robot.stamps[0] = stamp
        return robot

    def add_odometry(self, msg: OdometryIncrement) -> None:
        """Accumulate an increment; open a keyframe once the robot moved or turned enough."""
        robot = self._accept("odometry", msg.robot_id, msg.stamp)
        if robot is None:
            return
        if len(robot.stamps) == 1 and robot.stamps[0] > msg.start_stamp:
            robot.stamps[0] = msg.start_stamp
        robot.offset = compose(robot.offset, msg.delta)
        robot.distance_m += float(np.hypot(msg.dx, msg.dy))
        robot.angle_rad += abs(msg.dtheta)
        cfg = self.config
        if robot.distance_m >= cfg.keyframe_distance_m or robot.angle_rad >= cfg.keyframe_angle_rad:
            self._new_keyframe(robot, msg.stamp)

    def _new_keyframe(self, robot: _Robot, stamp: float) -> None:
        previous = robot.pose_keys[-1]
        key = keys.pose_key(robot.robot_id, len(robot.pose_keys))
        relative = planar_to_pose3(robot.offset)
        noise = odometry_noise(self.config, robot.distance_m, robot.angle_rad)
        self._graph.add(gtsam.BetweenFactorPose3(previous, key, relative, noise))
        self._initial.insert(key, self._pose_estimate(previous).compose(relative))
        self._odometry_variances[key] = np.asarray(noise.sigmas()) ** 2
        sigmas = np.asarray(noise.sigmas())
        robot.cum_var_xy.append(robot.cum_var_xy[-1] + sigmas[3] ** 2)
        robot.cum_var_theta.append(robot.cum_var_theta[-1] + sigmas[2] ** 2)
        robot.cum_distance_m.append(robot.cum_distance_m[-1] + robot.distance_m)
        robot.pose_keys.append(key)
        robot.stamps.append(stamp)
        robot.offset = np.zeros(3)
        robot.distance_m = 0.0
        robot.angle_rad = 0.0

    def _offset_covariance(self, robot: _Robot) -> np.ndarray:
        if robot.distance_m == 0.0 and robot.angle_rad == 0.0:
            return np.zeros((3, 3))
        return np.diag(odometry_sigmas(self.config, robot.distance_m, robot.angle_rad) ** 2)

    def add_landmarks(
        self, msg: LandmarkObservations, known_ids: list[int] | None = None
    ) -> list[AssociationResult]:
        """Associate the frame's points jointly (or use ``known_ids``) and add their factors.

        ``known_ids`` bypasses PDA with externally known identities; it exists only for the
        known-association reference evaluation and is never derived from the messages.
        """
        robot = self._accept("landmarks", msg.robot_id, msg.stamp)
        if robot is None or len(msg.points) == 0:
            return []
        if known_ids is not None and len(known_ids) != len(msg.points):
            raise ValueError("known_ids needs one id per observed point")
        points = np.asarray(msg.points, dtype=float).reshape(-1, 3)
        finite = np.isfinite(points).all(axis=1)
        if not finite.all():  # non-finite points are skipped (counted), the rest are used
            self.skipped_messages["landmark_points"] = self.skipped_messages.get(
                "landmark_points", 0
            ) + int((~finite).sum())
        results = [AssociationResult(-1, False, {}) for _ in points]
        if not finite.any():
            return results
        frame = self._frame(robot, points[finite])
        if known_ids is not None:
            ids = [int(k) for k, ok in zip(known_ids, finite, strict=True) if ok]
            used = self._add_known(frame, ids)
        else:
            used = self._associate_frame(robot, msg.stamp, frame)
        for i, result in zip(np.flatnonzero(finite), used, strict=True):
            results[i] = result
        return results

    def _frame(self, robot: _Robot, points: np.ndarray) -> dict:
        """Per point: z in the latest keyframe (with its covariance), z in the world, and
        the world covariance of T z from the sensor alone and with the pose marginal."""
        pose_key = robot.pose_keys[-1]
        pose = self._pose_estimate(pose_key)
        rotation = pose.rotation().matrix()
        pose_cov = self._pose_covariance(robot)
        offset_cov = self._offset_covariance(robot)
        frame: dict = {
            "pose_key": pose_key,
            "kf": [],
            "cov_kf": [],
            "world": [],
            "sensor": [],
            "cov": [],
        }
        for point in points:
            point_kf, cov_kf = self._to_keyframe(robot, point, offset_cov)
            frame["kf"].append(point_kf)
            frame["cov_kf"].append(cov_kf)
            frame["world"].append(np.asarray(pose.transformFrom(point_kf)))
            frame["sensor"].append(rotation @ cov_kf @ rotation.T)
            frame["cov"].append(measurement_covariance(rotation, point_kf, cov_kf, pose_cov))
        return frame

    def _to_keyframe(
        self, robot: _Robot, point: np.ndarray, offset_cov: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """A point seen now -> the robot's latest keyframe frame, with its covariance: the
        sensor's, rotated by the offset's heading, plus the offset's odometry uncertainty."""
        offset = robot.offset
        c, s = np.cos(offset[2]), np.sin(offset[2])
        offset_rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        rotated = offset_rot @ point
        point_kf = rotated + np.array([offset[0], offset[1], 0.0])
        jac_offset = np.array([[1.0, 0.0, -rotated[1]], [0.0, 1.0, rotated[0]], [0.0, 0.0, 0.0]])
        sensor_cov = sensor_covariance(self.config, point)
        cov_kf = offset_rot @ sensor_cov @ offset_rot.T + jac_offset @ offset_cov @ jac_offset.T
        return point_kf, cov_kf

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
        if int(observer_id) == int(observed_id):
            raise ValueError(f"robot {observer_id} cannot observe itself")
        observed = self._robots.get(int(observed_id))
        if observed is None:
            raise SlamError(f"observation of robot {observed_id}, which has no start pose")
        point = np.asarray(point, dtype=float).reshape(3)
        robot = self._accept("robots", observer_id, stamp)
        if robot is None:
            return False
        if not np.isfinite(point).all():
            self.skipped_messages["robot_points"] = self.skipped_messages.get("robot_points", 0) + 1
            return False
        point_kf, cov_kf = self._to_keyframe(robot, point, self._offset_covariance(robot))
        target_var = self._offset_covariance(observed)[0, 0]
        cov_kf = cov_kf + np.diag([target_var, target_var, 0.0])
        noise = observation_noise(cov_kf, 1.0, self.config.huber_k)
        target = np.array([observed.offset[0], observed.offset[1], 0.0])
        self._graph.add(
            robot_observation_factor(
                robot.pose_keys[-1], observed.pose_keys[-1], point_kf, target, noise
            )
        )
        self.robot_observations += 1
        return True

    def _add_factor(self, pose_key: int, index: int, point_kf, cov_kf, probability: float) -> None:
        noise = observation_noise(cov_kf, probability, self.config.huber_k)
        self._graph.add(observation_factor(pose_key, keys.landmark_key(index), point_kf, noise))

    def _add_known(self, frame: dict, known_ids: list[int]) -> list[AssociationResult]:
        results = []
        for n, known in enumerate(known_ids):
            index = self._known_landmarks.get(int(known))
            is_new = index is None
            if is_new:
                index = self._new_landmark(frame["world"][n], frame["cov"][n])
                self._known_landmarks[int(known)] = index
            self._add_factor(frame["pose_key"], index, frame["kf"][n], frame["cov_kf"][n], 1.0)
            results.append(AssociationResult(index, is_new, {index: 1.0}))
        return results

    def _reference(self, robot: _Robot) -> tuple[int | None, gtsam.Pose3, np.ndarray]:
        """The robot's latest *optimised* keyframe (None before the first update), its
        pose, and its 6x6 covariance plus the odometry variances of the pending keyframes
        after it (the pose whose cross-covariances with the landmarks iSAM2 can give)."""
        pending = np.zeros(6)
        for key in reversed(robot.pose_keys):
            if self._estimate.exists(key):
                return key, self._estimate.atPose3(key), self._marginal(key) + np.diag(pending)
            pending = pending + self._odometry_variances.get(key, 0.0)
        first = robot.pose_keys[0]
        return None, self._pose_estimate(first), self._pose_covariance(robot)

    def _landmark_blocks(
        self, ref_key: int | None, columns: list[int]
    ) -> tuple[list[np.ndarray], list[np.ndarray | None]]:
        """Marginal covariance of each landmark column and its cross-covariance with the
        reference pose (one iSAM2 joint marginal for the frame; None where unavailable)."""
        lm_covs: list[np.ndarray] = []
        cross: list[np.ndarray | None] = []
        optimised = [
            i
            for i in columns
            if i not in self._pending_landmark_covs and self._estimate.exists(keys.landmark_key(i))
        ]
        joint = None
        if ref_key is not None and optimised:
            query = [ref_key] + [keys.landmark_key(i) for i in optimised]
            try:
                joint = self._isam.jointMarginalCovariance(query)
            except _GTSAM_ERRORS:
                joint = None
        for i in columns:
            lkey = keys.landmark_key(i)
            if joint is not None and i in optimised:
                lm_covs.append(np.asarray(joint.at(lkey, lkey)))
                cross.append(np.asarray(joint.at(ref_key, lkey)))
            else:
                lm_covs.append(self._landmark_covariance(i))
                cross.append(None)
        return lm_covs, cross

    def _associate_frame(self, robot: _Robot, stamp: float, frame: dict) -> list[AssociationResult]:
        """Joint association of one frame (see :mod:`acslam.slam.association`).

        Columns are the confirmed landmarks within the Euclidean pre-gate of some point and
        this robot's live tentative landmarks. Innovation covariances use the pose-landmark
        cross-covariance from iSAM2 for confirmed landmarks, and for a tentative one the
        odometry chain between the keyframe it was last seen from and now.
        """
        cfg = self.config
        gate = cfg.association_mahalanobis_gate
        self._expire_tentatives(robot.robot_id, stamp)
        world = np.array(frame["world"])
        n_points = len(world)
        per_point = [
            euclidean_gate(p, self._landmark_positions, self._gate_radius(cov))
            for p, cov in zip(world, frame["cov"], strict=True)
        ]
        confirmed = sorted({int(i) for g in per_point for i in g})
        tentatives = [t for t in self._tentatives if t.robot_id == robot.robot_id]
        n_cols = len(confirmed) + len(tentatives)
        d2 = np.full((n_points, n_cols), np.inf)
        log_norm = np.zeros((n_points, n_cols))
        if n_cols:
            ref_key, ref_pose, ref_cov = self._reference(robot)
            ref_rot = ref_pose.rotation().matrix()
            lm_covs, cross = self._landmark_blocks(ref_key, confirmed)
            col_of = {i: c for c, i in enumerate(confirmed)}
            now_index = len(robot.pose_keys) - 1
            tent_geometry = []
            for t in tentatives:
                key, z_kf, cov_kf = t.observations[-1]
                pose = self._pose_estimate(key)
                rot = pose.rotation().matrix()
                tent_geometry.append((np.asarray(pose.transformFrom(z_kf)), rot @ cov_kf @ rot.T))
            for n in range(n_points):
                lever = pose_lever_jacobian(ref_rot, np.asarray(ref_pose.transformTo(world[n])))
                for i in per_point[n]:
                    c = col_of[int(i)]
                    s = innovation_covariance(
                        lever, ref_cov, lm_covs[c], cross[c], frame["sensor"][n]
                    )
                    self._score(d2, log_norm, n, c, world[n] - self._landmark_positions[i], s)
                rho2 = float(frame["kf"][n][:2] @ frame["kf"][n][:2])
                for k, t in enumerate(tentatives):
                    position, cov = tent_geometry[k]
                    innovation = world[n] - position
                    if np.linalg.norm(innovation) > cfg.association_gate_m:
                        continue
                    chain = self._chain_variance(robot, t.kf_index, now_index, rho2)
                    s = frame["sensor"][n] + cov + np.diag([chain, chain, 0.0])
                    self._score(d2, log_norm, n, len(confirmed) + k, innovation, s)
        assigned = assign_frame(d2, gate)
        results: list[AssociationResult] = []
        new_points: list[int] = []
        for n in range(n_points):
            others = np.zeros(n_cols, dtype=bool)
            for m in range(n_points):
                if m != n and assigned[m] >= 0:
                    others[assigned[m]] = True
            column = assigned[n]
            if column < 0:
                near = d2[n] < cfg.new_landmark_mahalanobis_gate
                if (near & ~others).any():
                    self.dropped_ambiguous += 1
                    results.append(AssociationResult(-1, False, {}))
                else:
                    new_points.append(n)
                    results.append(AssociationResult(-1, True, {}, tentative=True))
                continue
            # A confirmed landmark in the gate takes precedence over this robot's tentatives:
            # a tentative that competes with one is most likely its duplicate (seen by this
            # robot before another robot's observations confirmed it), and letting the two
            # split the probability would drop every point until the tentative expires.
            excluded = others.copy()
            n_conf = len(confirmed)
            row = np.where(others[:n_conf], np.inf, d2[n, :n_conf])
            if column >= n_conf and n_conf and row.min() <= gate:
                column = int(np.argmin(row))
            if column < n_conf:
                excluded[n_conf:] = True
            cols, probs = exclusive_probabilities(d2[n], log_norm[n], gate, excluded)
            best = float(probs[cols == column][0])
            if best < cfg.association_min_best_probability:
                self.dropped_ambiguous += 1
                results.append(AssociationResult(-1, False, {}))
                continue
            if column >= len(confirmed):
                results.append(
                    self._observe_tentative(
                        robot, stamp, tentatives[column - len(confirmed)], frame, n
                    )
                )
                continue
            soft = {
                confirmed[c]: float(p)
                for c, p in zip(cols, probs, strict=True)
                if c < len(confirmed) and p >= cfg.association_min_probability
            }
            total = sum(soft.values())
            soft = {i: p / total for i, p in soft.items()}
            for index, probability in soft.items():
                self._add_factor(
                    frame["pose_key"], index, frame["kf"][n], frame["cov_kf"][n], probability
                )
            results.append(AssociationResult(confirmed[column], False, soft))
        for n in new_points:
            tentative = _Tentative(robot.robot_id, [], len(robot.pose_keys) - 1, stamp)
            self._tentatives.append(tentative)
            results[n] = self._observe_tentative(robot, stamp, tentative, frame, n)
        return results

    def _gate_radius(self, point_cov: np.ndarray) -> float:
        """Euclidean pre-gate of a point: ``association_gate_m``, widened to the Mahalanobis
        gate of the point's own world covariance (pose marginal included) so that a robot
        whose estimate drifted further than the fixed gate can still find its landmarks."""
        widest = float(np.linalg.eigvalsh(point_cov)[-1])
        return max(
            self.config.association_gate_m,
            float(np.sqrt(self.config.association_mahalanobis_gate * widest)),
        )

    @staticmethod
    def _score(d2, log_norm, n: int, c: int, innovation: np.ndarray, s: np.ndarray) -> None:
        d2[n, c] = mahalanobis_sq(innovation, s)
        if np.isfinite(d2[n, c]):
            log_norm[n, c] = 0.5 * (3 * np.log(2 * np.pi) + np.linalg.slogdet(s)[1])

    def _observe_tentative(
        self, robot: _Robot, stamp: float, tentative: _Tentative, frame: dict, n: int
    ) -> AssociationResult:
        """Buffer an observation of a tentative landmark; confirm it once seen often enough."""
        tentative.observations.append((frame["pose_key"], frame["kf"][n], frame["cov_kf"][n]))
        tentative.kf_index = len(robot.pose_keys) - 1
        tentative.stamp = stamp
        if len(tentative.observations) < self.config.landmark_confirmations:
            self.tentative_observations += 1
            return AssociationResult(-1, True, {}, tentative=True)
        self._tentatives.remove(tentative)
        index = self._new_landmark(frame["world"][n], frame["cov"][n])
        for pose_key, z_kf, cov_kf in tentative.observations:
            self._add_factor(pose_key, index, z_kf, cov_kf, 1.0)
        return AssociationResult(index, True, {index: 1.0})

    def _chain_variance(self, robot: _Robot, since: int, now: int, lever_sq: float) -> float:
        """Planar position variance the odometry chain from keyframe ``since`` to ``now``
        adds to a point seen at squared range ``lever_sq`` (heading error x lever arm)."""
        var_xy = robot.cum_var_xy[now] - robot.cum_var_xy[since]
        var_th = robot.cum_var_theta[now] - robot.cum_var_theta[since]
        length = robot.cum_distance_m[now] - robot.cum_distance_m[since]
        return var_xy + var_th * (length**2 + lever_sq)

    def _expire_tentatives(self, robot_id: int, stamp: float) -> None:
        timeout = self.config.tentative_timeout_s
        keep = []
        for t in self._tentatives:
            if t.robot_id == robot_id and stamp - t.stamp > timeout:
                self.expired_tentatives += 1
            else:
                keep.append(t)
        self._tentatives = keep

    def _new_landmark(self, position: np.ndarray, covariance: np.ndarray) -> int:
        index = len(self._landmark_positions)
        self._initial.insert(keys.landmark_key(index), gtsam.Point3(*position))
        self._landmark_positions = np.vstack([self._landmark_positions, position])
        self._pending_landmark_covs[index] = covariance
        return index

    def add_scan(self, msg: LidarScan) -> int | None:
        """Store a scan with its robot's latest keyframe and the odometry offset since it.

        Returns the scan's index (for :meth:`scan_pose`), or None if it was skipped.
        """
        robot = self._accept("scan", msg.robot_id, msg.stamp)
        if robot is None:
            return None
        index = len(self._scans)
        keyframe = robot.pose_keys[-1]
        self._scans.append((msg, keyframe, robot.offset.copy()))
        self._scans_by_keyframe.setdefault(keyframe, []).append(index)
        return index

    # ------------------------------------------------------------------ optimisation

    def update(self, extra_iterations: int = 0) -> None:
        """Hand the buffered factors and values to iSAM2, then refresh the cached estimate.

        One iSAM2 update is one Gauss-Newton step on the affected part of the graph;
        ``extra_iterations`` more steps help after a large correction (a Huber-weighted
        loop closure converges by reweighting over several steps).
        """
        if self._graph.size() == 0 and self._initial.size() == 0 and extra_iterations == 0:
            return
        start = time.perf_counter()
        try:
            self._isam.update(self._graph, self._initial)
            for _ in range(extra_iterations):
                self._isam.update()
            estimate = self._isam.calculateEstimate()
        except _GTSAM_ERRORS as exc:
            raise SlamError(f"iSAM2 update failed: {type(exc).__name__}: {exc}") from None
        finally:
            self._graph = gtsam.NonlinearFactorGraph()
            self._initial = gtsam.Values()
        self.update_durations_s.append(time.perf_counter() - start)
        self._estimate = estimate
        self._marginals.clear()
        self._pending_landmark_covs.clear()
        if len(self._landmark_positions):
            self._landmark_positions = np.asarray(gtsam.utilities.extractPoint3(estimate))
        self._moved = self._report_moves(*self._pose_positions(estimate))

    def _report_moves(self, pose_keys: np.ndarray, positions: np.ndarray) -> list[tuple[int, int]]:
        """Keyframes now more than correction_threshold_m from where they were last
        reported; their reported position becomes the current one.

        Measured against the last *report*, not the last update: a keyframe creeping by
        less than the threshold per update (a long loop's correction spread over many
        updates) is still reported once its total move exceeds the threshold, so maps
        that follow the reports never lag the estimate by more than the threshold.
        """
        last = positions.copy()
        if len(self._reported_keys):
            rows = np.searchsorted(self._reported_keys, pose_keys).clip(
                0, len(self._reported_keys) - 1
            )
            reported = self._reported_keys[rows] == pose_keys
            last[reported] = self._reported_positions[rows[reported]]
        shift = np.linalg.norm(positions - last, axis=1)
        moved = shift > self.config.correction_threshold_m
        last[moved] = positions[moved]
        self._reported_keys, self._reported_positions = pose_keys, last
        return [keys.decode_pose_key(int(k)) for k in pose_keys[moved]]

    @staticmethod
    def _pose_positions(values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
        """Sorted pose keys of ``values`` and their (N, 3) translations."""
        all_keys = np.asarray(values.keys(), dtype=np.uint64)
        pose_keys = all_keys[(all_keys >> np.uint64(56)) == _POSE_CHAR_CODE]
        if len(pose_keys) == 0:
            return pose_keys, np.zeros((0, 3))
        table = np.asarray(gtsam.utilities.extractPose3(values)).reshape(-1, 12)
        return np.sort(pose_keys), table[:, 9:12]

    def _marginal(self, key: int) -> np.ndarray:
        cov = self._marginals.get(key)
        if cov is None:
            try:
                cov = np.asarray(self._isam.marginalCovariance(key))
            except _GTSAM_ERRORS as exc:
                raise SlamError(
                    f"marginal covariance of {keys.describe(key)} failed: {exc}"
                ) from None
            self._marginals[key] = cov
        return cov

    def _pose_estimate(self, key: int) -> gtsam.Pose3:
        if self._estimate.exists(key):
            return self._estimate.atPose3(key)
        return self._initial.atPose3(key)

    def _pose_covariance(self, robot: _Robot) -> np.ndarray:
        """6x6 marginal of the latest keyframe; a pending one adds its odometry variances."""
        pending = 0.0
        for key in reversed(robot.pose_keys):
            if self._estimate.exists(key):
                return self._marginal(key) + np.diag(np.zeros(6) + pending)
            pending = pending + self._odometry_variances.get(key, 0.0)
        return np.diag(prior_noise(self.config).sigmas() ** 2 + pending)

    def _landmark_covariance(self, index: int) -> np.ndarray:
        pending = self._pending_landmark_covs.get(index)
        return pending if pending is not None else self._marginal(keys.landmark_key(index))

    # ------------------------------------------------------------------ queries

    @property
    def robot_ids(self) -> list[int]:
        return sorted(self._robots)

    def keyframe_count(self, robot_id: int) -> int:
        return len(self._robots[robot_id].pose_keys)

    def latest_pose(self, robot_id: int) -> np.ndarray:
        """``[x, y, theta]``: the latest keyframe's estimate composed with the odometry since."""
        robot = self._robots[robot_id]
        return compose(pose3_to_planar(self._pose_estimate(robot.pose_keys[-1])), robot.offset)

    def latest_covariance(self, robot_id: int) -> np.ndarray:
        """World-frame 3x3 covariance of :meth:`latest_pose` (keyframe marginal + offset)."""
        robot = self._robots[robot_id]
        keyframe = pose3_to_planar(self._pose_estimate(robot.pose_keys[-1]))
        cov = _planar_covariance(self._pose_covariance(robot), keyframe[2])
        ja, jb = planar_compose_jacobians(keyframe, robot.offset)
        return ja @ cov @ ja.T + jb @ self._offset_covariance(robot) @ jb.T

    def landmarks(self) -> np.ndarray:
        """(M, 3) landmark positions in the world frame; row i is landmark i."""
        return self._landmark_positions.copy()

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        """Keyframe stamps (N,) and optimised ``[x, y, theta]`` poses (N, 3) of one robot."""
        robot = self._robots[robot_id]
        poses = np.array([pose3_to_planar(self._pose_estimate(k)) for k in robot.pose_keys])
        return np.array(robot.stamps), poses

    def moved_keyframes(self) -> list[tuple[int, int]]:
        """``(robot_id, index)`` of keyframes the last update left more than
        correction_threshold_m from where they were last reported (see _report_moves)."""
        return list(self._moved)

    def scan_pose(self, index: int) -> np.ndarray:
        """Current world pose ``[x, y, theta]`` of stored scan ``index``."""
        _, key, offset = self._scans[index]
        return compose(pose3_to_planar(self._pose_estimate(key)), offset)

    def scan_keyframe(self, index: int) -> tuple[int, int]:
        """``(robot_id, keyframe_index)`` stored scan ``index`` is attached to."""
        return keys.decode_pose_key(self._scans[index][1])

    def add_scan_constraint(
        self,
        index_a: int,
        index_b: int,
        relative: np.ndarray,
        covariance: np.ndarray,
        robust: bool,
    ) -> None:
        """A scan match as a factor between the two scans' keyframes.

        ``relative`` is scan b's sensor pose in scan a's frame with its 3x3 covariance
        ``[x, y, theta]``; with the scans' offsets from their keyframes it becomes
        kf_a^-1 kf_b = off_a * relative * off_b^-1. The covariance is rotated by off_a's
        heading (offsets are the odometry since the keyframe: small). ``robust`` adds a
        Huber kernel (loop closures).
        """
        _, key_a, offset_a = self._scans[index_a]
        _, key_b, offset_b = self._scans[index_b]
        between_keyframes = compose(compose(offset_a, relative), inverse(offset_b))
        c, s = np.cos(offset_a[2]), np.sin(offset_a[2])
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        planar = rotation @ np.asarray(covariance, dtype=float) @ rotation.T
        full = np.diag(np.full(6, self.config.planar_sigma**2))
        order = [3, 4, 2]  # GTSAM Pose3 tangent: rotation (roll, pitch, yaw), then x, y, z
        full[np.ix_(order, order)] = planar
        noise: gtsam.noiseModel.Base = gtsam.noiseModel.Gaussian.Covariance(full)
        if robust:
            noise = gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Huber.Create(self.config.huber_k), noise
            )
        self._graph.add(
            gtsam.BetweenFactorPose3(key_a, key_b, planar_to_pose3(between_keyframes), noise)
        )

    def scans_of_keyframes(self, keyframes: list[tuple[int, int]]) -> list[int]:
        """Indices of the scans attached to the ``(robot_id, index)`` keyframes."""
        found: list[int] = []
        for robot_id, index in keyframes:
            found.extend(self._scans_by_keyframe.get(keys.pose_key(robot_id, index), []))
        return found

    def posed_scans(self) -> list[tuple[LidarScan, np.ndarray]]:
        """Every stored scan with its current world pose ``[x, y, theta]``."""
        return [(scan, self.scan_pose(i)) for i, (scan, _, _) in enumerate(self._scans)]
