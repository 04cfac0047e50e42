"""Centralized multi-robot SLAM back end: one iSAM2 over all robots' poses and landmarks.

Graph (thesis eqs. 4.17-4.20): a prior on each robot's known start pose, SE(3) odometry
between-factors between consecutive keyframes, and Huber-robust landmark observation
factors, softly associated by PDA (eqs. 4.21-4.24) to landmarks shared by all robots.

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
from acslam.errors import AcslamError
from acslam.geometry import compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement
from acslam.slam import keys
from acslam.slam.association import (
    euclidean_gate,
    measurement_covariance,
    score_candidates,
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
    sensor_covariance,
)

_GTSAM_ERRORS = (RuntimeError, ValueError, IndexError, KeyError)
_POSE_CHAR_CODE = ord(keys.POSE_CHAR)


class SlamError(AcslamError):
    """The optimiser failed (e.g. an indeterminant linear system); names the operation."""


@dataclass(frozen=True)
class AssociationResult:
    """What one observed point became: its most probable landmark and all probabilities.

    ``landmark`` is -1 (and ``probabilities`` empty) for an ambiguous point that was dropped.
    """

    landmark: int
    is_new: bool
    probabilities: dict[int, float]


@dataclass
class _Robot:
    robot_id: int
    pose_keys: list[int]
    stamps: list[float]
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance_m: float = 0.0
    angle_rad: float = 0.0
    last_stamp: dict[str, float] = field(default_factory=dict)


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
        params.relinearizeSkip = 1
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
        self.skipped_messages: dict[str, int] = {"odometry": 0, "landmarks": 0, "scan": 0}
        self.update_durations_s: list[float] = []
        self.dropped_ambiguous = 0
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
            self.skipped_messages[kind] += 1
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
        """Associate each point (PDA, or ``known_ids`` in reference runs) and add its factors.

        ``known_ids`` bypasses PDA with externally known identities; it exists only for the
        known-association reference evaluation and is never derived from the messages.
        """
        robot = self._accept("landmarks", msg.robot_id, msg.stamp)
        if robot is None or len(msg.points) == 0:
            return []
        if known_ids is not None and len(known_ids) != len(msg.points):
            raise ValueError("known_ids needs one id per observed point")
        cfg = self.config
        pose_key = robot.pose_keys[-1]
        pose = self._pose_estimate(pose_key)
        rotation = pose.rotation().matrix()
        pose_cov = self._pose_covariance(robot)
        offset = robot.offset
        offset_cov = self._offset_covariance(robot)
        c, s = np.cos(offset[2]), np.sin(offset[2])
        offset_rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        results = []
        for n, point in enumerate(msg.points):
            rotated = offset_rot @ point
            point_kf = rotated + np.array([offset[0], offset[1], 0.0])
            jac_offset = np.array(
                [[1.0, 0.0, -rotated[1]], [0.0, 1.0, rotated[0]], [0.0, 0.0, 0.0]]
            )
            sensor_cov = sensor_covariance(cfg, point)
            cov_kf = offset_rot @ sensor_cov @ offset_rot.T + jac_offset @ offset_cov @ jac_offset.T
            point_world = np.asarray(pose.transformFrom(point_kf))
            point_cov = measurement_covariance(rotation, point_kf, cov_kf, pose_cov)
            if known_ids is not None:
                probabilities = self._known_association(int(known_ids[n]))
            else:
                probabilities = self._associate(point_world, point_cov)
                if probabilities is None:
                    self.dropped_ambiguous += 1
                    results.append(AssociationResult(-1, False, {}))
                    continue
            is_new = not probabilities
            if is_new:
                index = self._new_landmark(point_world, point_cov)
                probabilities = {index: 1.0}
                if known_ids is not None:
                    self._known_landmarks[int(known_ids[n])] = index
            for index, probability in probabilities.items():
                noise = observation_noise(cov_kf, probability, cfg.huber_k)
                self._graph.add(
                    observation_factor(pose_key, keys.landmark_key(index), point_kf, noise)
                )
            best = max(probabilities, key=probabilities.__getitem__)
            results.append(AssociationResult(best, is_new, probabilities))
        return results

    def _known_association(self, known_id: int) -> dict[int, float]:
        index = self._known_landmarks.get(known_id)
        return {} if index is None else {index: 1.0}

    def _associate(self, point_world: np.ndarray, point_cov: np.ndarray) -> dict[int, float] | None:
        """PDA probabilities of the candidates; {} means a new landmark, None ambiguous."""
        cfg = self.config
        gated = euclidean_gate(point_world, self._landmark_positions, cfg.association_gate_m)
        if len(gated) == 0:
            return {}
        covs = np.array([self._landmark_covariance(int(i)) for i in gated])
        candidates = score_candidates(
            point_world,
            point_cov,
            gated,
            self._landmark_positions[gated],
            covs,
            cfg.association_mahalanobis_gate,
            cfg.association_min_likelihood,
        )
        if (
            len(candidates) == 0
            and candidates.nearest_mahalanobis**2 < cfg.new_landmark_mahalanobis_gate
        ):
            return None
        return {
            int(i): float(p)
            for i, p in zip(candidates.indices, candidates.probability, strict=True)
        }

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
        old_keys, old_positions = self._pose_positions(self._estimate)
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
        new_keys, new_positions = self._pose_positions(estimate)
        self._moved = []
        if len(old_keys):
            rows = np.searchsorted(new_keys, old_keys)
            shift = np.linalg.norm(new_positions[rows] - old_positions, axis=1)
            moved = old_keys[shift > self.config.correction_threshold_m]
            self._moved = [keys.decode_pose_key(int(k)) for k in moved]

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
        """``(robot_id, index)`` of keyframes moved > correction_threshold_m by the last update."""
        return list(self._moved)

    def scan_pose(self, index: int) -> np.ndarray:
        """Current world pose ``[x, y, theta]`` of stored scan ``index``."""
        _, key, offset = self._scans[index]
        return compose(pose3_to_planar(self._pose_estimate(key)), offset)

    def scans_of_keyframes(self, keyframes: list[tuple[int, int]]) -> list[int]:
        """Indices of the scans attached to the ``(robot_id, index)`` keyframes."""
        found: list[int] = []
        for robot_id, index in keyframes:
            found.extend(self._scans_by_keyframe.get(keys.pose_key(robot_id, index), []))
        return found

    def posed_scans(self) -> list[tuple[LidarScan, np.ndarray]]:
        """Every stored scan with its current world pose ``[x, y, theta]``."""
        return [(scan, self.scan_pose(i)) for i, (scan, _, _) in enumerate(self._scans)]
