"""Centralized multi-robot SLAM back end: one iSAM2 over all robots' poses and landmarks.

Graph (thesis eqs. 4.17-4.20): a prior on each robot's known start pose, planar odometry
between-factors (``Pose2``: see :mod:`acslam.slam.factors`) between consecutive keyframes,
and Huber-robust landmark observation factors, softly associated by PDA (eqs. 4.21-4.24)
to landmarks shared by all robots, and Huber-robust factors between two robots' keyframes
when one robot sees another.

Keyframes: a robot gets a new pose variable only when the odometry accumulated since its
last keyframe exceeds ``keyframe_distance_m`` of path or ``keyframe_angle_rad`` of turn,
so the graph grows with distance travelled, not with time; where its team already has
keyframes, only every ``mapped_keyframe_distance_m`` (:mod:`acslam.slam.keyframe_coverage`),
so it grows with the mapped area rather than with every pass. Landmark observations and
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
from acslam.geometry import compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement
from acslam.pipeline.stages import AssociationResult
from acslam.slam import keys
from acslam.slam.factors import (
    odometry_noise,
    odometry_sigmas,
    planar_compose_jacobians,
    planar_to_pose2,
    pose2_to_planar,
    prior_noise,
    rotation_about_z,
)
from acslam.slam.keyframe_coverage import KeyframeCoverage
from acslam.slam.keyframe_scans import KeyframeScans
from acslam.slam.landmark_association import LandmarkAssociation, chain_variance
from acslam.slam.odometry_calibration import OdometryCalibration

_GTSAM_ERRORS = (RuntimeError, ValueError, IndexError, KeyError)
_POSE_CHAR_CODE = ord(keys.POSE_CHAR)


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
    # The latest iSAM2 marginal of one of this robot's keyframes: (keyframe index, 3x3).
    pose_marginal: tuple[int, np.ndarray] | None = None
    calibration: OdometryCalibration | None = None


def _planar_covariance(body_cov: np.ndarray, theta_rad: float) -> np.ndarray:
    """Pose2 body-frame 3x3 marginal -> world-frame ``[x, y, theta]`` covariance."""
    rot = rotation_about_z(theta_rad)
    return rot @ body_cov @ rot.T


class SlamBackend:
    """One iSAM2 for the whole team. Feed messages, call :meth:`update`, query the estimate."""

    def __init__(
        self,
        config: SlamConfig,
        starts: dict[int, np.ndarray],
        start_sigmas: dict[int, np.ndarray] | None = None,
    ) -> None:
        """``start_sigmas``: ``[x, y, theta]`` sigmas of a start known less well than the
        config's prior (a robot placed by a merge of frames), by robot id."""
        if not starts:
            raise ValueError("SlamBackend needs the start pose of at least one robot")
        self.config = config
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(config.isam_relinearize_threshold)
        params.relinearizeSkip = config.isam_relinearize_skip
        params.setFactorization(config.isam_factorization)
        self._isam = gtsam.ISAM2(params)
        # Landmark and sighting factors are CustomFactors: iSAM2 linearizes them with its
        # whole linearization point, which pybind11 copies into a new Python Values for
        # every call (O(graph) per factor) unless a Python object already wraps that
        # Values. This view is such an object (a reference into iSAM2, not a copy), so the
        # callbacks receive it as is.
        self._linearization_point = self._isam.getLinearizationPoint()
        self._graph = gtsam.NonlinearFactorGraph()
        self._initial = gtsam.Values()
        self._estimate = gtsam.Values()
        self._robots: dict[int, _Robot] = {}
        self._landmark_positions = np.zeros((0, 3))
        self._pending_landmark_covs: dict[int, np.ndarray] = {}
        # Each landmark's latest known covariance: its first one, then every marginal
        # iSAM2 gave for it (see last_landmark_covariance).
        self._last_landmark_covs: dict[int, np.ndarray] = {}
        self._marginals: dict[int, np.ndarray] = {}
        self._odometry_variances: dict[int, np.ndarray] = {}
        self._moved: list[tuple[int, int]] = []
        # Per pose key, the position last reported (by moved_keyframes, or when first
        # estimated): users placed the keyframe's scans there.
        self._reported_keys = np.zeros(0, dtype=np.uint64)
        self._reported_positions = np.zeros((0, 2))
        # The estimate's pose keys (sorted) and their ``[x, y, theta]`` rows.
        self._pose_keys = np.zeros(0, dtype=np.uint64)
        self._pose_table = np.zeros((0, 3))
        self.skipped_messages: dict[str, int] = {"odometry": 0, "landmarks": 0, "scan": 0}
        self.update_durations_s: list[float] = []
        self.association = LandmarkAssociation(self)
        self.scans = KeyframeScans(self)
        self._coverage = KeyframeCoverage(
            config.mapped_space_radius_m, config.mapped_space_min_path_m
        )
        for robot_id, start in starts.items():
            start = np.asarray(start, dtype=float)
            key = keys.pose_key(int(robot_id), 0)
            calibration = OdometryCalibration(config) if config.odometry_calibration else None
            self._robots[int(robot_id)] = _Robot(
                int(robot_id), [key], [float("nan")], calibration=calibration
            )
            sigmas = (start_sigmas or {}).get(int(robot_id))
            noise = (
                prior_noise(config)
                if sigmas is None
                else gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sigmas, dtype=float))
            )
            self._graph.add(gtsam.PriorFactorPose2(key, planar_to_pose2(start), noise))
            self._initial.insert(key, planar_to_pose2(start))
            self._coverage.add(int(robot_id), float(start[0]), float(start[1]), 0.0)

    # ------------------------------------------------------------------ input

    def accept(self, kind: str, robot_id: int, stamp: float) -> _Robot | None:
        """The message's robot, or None (counted) if the message is older than the last
        of its kind from that robot."""
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
        robot = self.accept("odometry", msg.robot_id, msg.stamp)
        if robot is None:
            return
        if len(robot.stamps) == 1 and robot.stamps[0] > msg.start_stamp:
            robot.stamps[0] = msg.start_stamp
        if robot.calibration is not None:
            msg = robot.calibration.correct(msg)
        robot.offset = compose(robot.offset, msg.delta)
        robot.distance_m += float(np.hypot(msg.dx, msg.dy))
        robot.angle_rad += abs(msg.dtheta)
        cfg = self.config
        if robot.angle_rad >= cfg.keyframe_angle_rad or (
            robot.distance_m >= cfg.keyframe_distance_m and not self._in_mapped_space(robot)
        ):
            self._new_keyframe(robot, msg.stamp)

    def _in_mapped_space(self, robot: _Robot) -> bool:
        """Whether the robot may drive on to ``mapped_keyframe_distance_m`` before its
        next keyframe: it is short of that, and its team already keyframed where it is."""
        if robot.distance_m >= self.config.mapped_keyframe_distance_m:
            return False
        x_m, y_m, _ = self.latest_pose(robot.robot_id)
        path_m = robot.cum_distance_m[-1] + robot.distance_m
        return self._coverage.covers(robot.robot_id, x_m, y_m, path_m)

    def _new_keyframe(self, robot: _Robot, stamp: float) -> None:
        previous = robot.pose_keys[-1]
        key = keys.pose_key(robot.robot_id, len(robot.pose_keys))
        relative = planar_to_pose2(robot.offset)
        noise = odometry_noise(self.config, robot.distance_m, robot.angle_rad)
        self._graph.add(gtsam.BetweenFactorPose2(previous, key, relative, noise))
        pose = self.pose_estimate(previous).compose(relative)
        self._initial.insert(key, pose)
        self._odometry_variances[key] = np.asarray(noise.sigmas()) ** 2
        sigmas = np.asarray(noise.sigmas())
        robot.cum_var_xy.append(robot.cum_var_xy[-1] + sigmas[0] ** 2)
        robot.cum_var_theta.append(robot.cum_var_theta[-1] + sigmas[2] ** 2)
        robot.cum_distance_m.append(robot.cum_distance_m[-1] + robot.distance_m)
        self._coverage.add(robot.robot_id, pose.x(), pose.y(), robot.cum_distance_m[-1])
        robot.pose_keys.append(key)
        robot.stamps.append(stamp)
        robot.offset = np.zeros(3)
        robot.distance_m = 0.0
        robot.angle_rad = 0.0

    def calibrate_odometry(
        self,
        robot_id: int,
        start_s: float,
        end_s: float,
        relative: np.ndarray,
        covariance: np.ndarray,
    ) -> None:
        """A verified scan match of the robot's sensor between two stamps, for its
        odometry calibration (a no-op when calibration is off)."""
        robot = self._robots[int(robot_id)]
        if robot.calibration is not None:
            robot.calibration.update(start_s, end_s, relative, covariance)

    def odometry_calibrations(self) -> dict[int, dict[str, float | int]]:
        """Per robot, its odometry calibration's estimate (none when calibration is off)."""
        return {
            robot_id: robot.calibration.summary()
            for robot_id, robot in self._robots.items()
            if robot.calibration is not None
        }

    def add_landmarks(self, msg: LandmarkObservations) -> list[AssociationResult]:
        """See :meth:`LandmarkAssociation.add_landmarks`."""
        return self.association.add_landmarks(msg)

    def add_robot_observation(
        self, observer_id: int, observed_id: int, stamp: float, point: np.ndarray
    ) -> bool:
        """See :meth:`LandmarkAssociation.add_robot_observation`."""
        return self.association.add_robot_observation(observer_id, observed_id, stamp, point)

    def add_scan(self, msg: LidarScan) -> int | None:
        """See :meth:`KeyframeScans.add`."""
        return self.scans.add(msg)

    # ------------------------------------------------------------------ for collaborators

    def robot(self, robot_id: int) -> _Robot | None:
        return self._robots.get(int(robot_id))

    def add_factor(self, factor: gtsam.NonlinearFactor) -> None:
        """Buffer a factor for the next :meth:`update`."""
        self._graph.add(factor)

    @property
    def landmark_positions(self) -> np.ndarray:
        """(M, 3) current landmark positions (read-only use)."""
        return self._landmark_positions

    def offset_covariance(self, robot: _Robot) -> np.ndarray:
        """3x3 covariance of the odometry since the robot's latest keyframe."""
        if robot.distance_m == 0.0 and robot.angle_rad == 0.0:
            return np.zeros((3, 3))
        return np.diag(odometry_sigmas(self.config, robot.distance_m, robot.angle_rad) ** 2)

    def odometry_chain_covariance(self, robot_id: int, since: int, now: int) -> np.ndarray:
        """3x3 covariance ``[x, y, theta]`` of the odometry from keyframe ``since`` to
        ``now`` of one robot: the sum of its keyframes' variances, the heading's acting
        over the chain's length on x and y (isotropic, so in either end's frame)."""
        robot = self._robots[int(robot_id)]
        var_xy = chain_variance(robot, since, now, 0.0)
        var_theta = robot.cum_var_theta[now] - robot.cum_var_theta[since]
        return np.diag([var_xy, var_xy, var_theta])

    def new_landmark(self, position: np.ndarray, covariance: np.ndarray) -> int:
        """Add a landmark at ``position`` with its first covariance; returns its index."""
        index = len(self._landmark_positions)
        self._initial.insert(keys.landmark_key(index), gtsam.Point3(*position))
        self._landmark_positions = np.vstack([self._landmark_positions, position])
        self._pending_landmark_covs[index] = covariance
        self._last_landmark_covs[index] = covariance
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
        self._pose_keys, self._pose_table = self._pose_rows(estimate)
        self._moved = self._report_moves(self._pose_keys, self._pose_table[:, :2])

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
    def _pose_rows(values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
        """Sorted pose keys of ``values`` and their (N, 3) ``[x, y, theta]`` rows."""
        all_keys = np.asarray(values.keys(), dtype=np.uint64)
        pose_keys = all_keys[(all_keys >> np.uint64(56)) == _POSE_CHAR_CODE]
        if len(pose_keys) == 0:
            return pose_keys, np.zeros((0, 3))
        table = np.asarray(gtsam.utilities.extractPose2(values)).reshape(-1, 3)
        return np.sort(pose_keys), table

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

    def reference(self, robot: _Robot) -> tuple[int | None, gtsam.Pose2, np.ndarray]:
        """The robot's latest *optimised* keyframe (None before the first update), its
        pose, and its 3x3 covariance (:meth:`_keyframe_marginal`) plus the odometry
        variances of the pending keyframes after it (the pose whose cross-covariances with
        the landmarks iSAM2 can give)."""
        index, pending = self._latest_optimised(robot)
        if index is None:
            first = robot.pose_keys[0]
            return None, self.pose_estimate(first), self.pose_covariance(robot)
        key = robot.pose_keys[index]
        covariance = self._keyframe_marginal(robot, index) + np.diag(pending)
        return key, self._estimate.atPose2(key), covariance

    def _latest_optimised(self, robot: _Robot) -> tuple[int | None, np.ndarray]:
        """Index of the robot's latest optimised keyframe (None before the first update)
        and the summed odometry variances of the pending keyframes after it."""
        pending = np.zeros(3)
        for index in range(len(robot.pose_keys) - 1, -1, -1):
            if self._estimate.exists(robot.pose_keys[index]):
                return index, pending
            pending = pending + self._odometry_variances.get(robot.pose_keys[index], 0.0)
        return None, pending

    def landmark_blocks(
        self, ref_key: int | None, columns: list[int]
    ) -> tuple[np.ndarray | None, list[np.ndarray], list[np.ndarray | None]]:
        """The reference pose's 3x3 marginal, and the marginal covariance of each landmark
        column and its cross-covariance with the reference pose, from one iSAM2 joint
        marginal (None where unavailable)."""
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
                self._last_landmark_covs[i] = lm_covs[-1]
            else:
                lm_covs.append(self._landmark_covariance(i))
                cross.append(None)
        pose_cov = None if joint is None else np.asarray(joint.at(ref_key, ref_key))
        return pose_cov, lm_covs, cross

    def pose_estimate(self, key: int) -> gtsam.Pose2:
        """The optimised pose of ``key``, or its initial guess before the first update."""
        if self._estimate.exists(key):
            return self._estimate.atPose2(key)
        return self._initial.atPose2(key)

    def planar_poses(self, pose_keys: np.ndarray) -> np.ndarray:
        """(k, 3) ``[x, y, theta]`` of many keyframes at once: :meth:`pose_estimate`,
        vectorised over the last update's estimate. Keyframes not optimised yet are read
        one by one."""
        pose_keys = np.asarray(pose_keys, dtype=np.uint64)
        rows = np.searchsorted(self._pose_keys, pose_keys)
        found = rows < len(self._pose_keys)
        found[found] = self._pose_keys[rows[found]] == pose_keys[found]
        poses = np.empty((len(pose_keys), 3))
        poses[found] = self._pose_table[rows[found]]
        for k in np.flatnonzero(~found):
            poses[k] = pose2_to_planar(self.pose_estimate(int(pose_keys[k])))
        return poses

    def pose_covariance(self, robot: _Robot) -> np.ndarray:
        """3x3 marginal of the latest optimised keyframe (:meth:`_keyframe_marginal`); a
        pending keyframe adds its odometry variances."""
        index, pending = self._latest_optimised(robot)
        if index is None:
            return np.diag(prior_noise(self.config).sigmas() ** 2 + pending)
        return self._keyframe_marginal(robot, index) + np.diag(pending)

    def _keyframe_marginal(self, robot: _Robot, index: int) -> np.ndarray:
        """3x3 marginal of the robot's optimised keyframe ``index``, or a bound on it.

        An iSAM2 marginal costs more as the graph grows, and association wants one in
        every frame. Within ``association_covariance_reuse_keyframes`` keyframes of the
        last one computed for this robot, that one serves, carried along the odometry
        chain since (first order: P' = Ad(T^-1) P Ad(T^-1)^T + Q per step, in GTSAM's
        body-frame tangent): the marginal of the graph of that update with only the
        odometry since added. What the graph learnt besides only shrinks a marginal, so
        the bound errs on the wide side (as the landmark covariances reused in
        :meth:`LandmarkAssociation._reusable` do).
        """
        cached = robot.pose_marginal
        if cached is not None:
            since, covariance = cached
            if 0 <= index - since < self.config.association_covariance_reuse_keyframes:
                for step in range(since + 1, index + 1):
                    previous, key = robot.pose_keys[step - 1], robot.pose_keys[step]
                    relative = self.pose_estimate(previous).between(self.pose_estimate(key))
                    adjoint = relative.inverse().AdjointMap()
                    covariance = adjoint @ covariance @ adjoint.T + np.diag(
                        self._odometry_variances[key]
                    )
                return covariance
        covariance = self._marginal(robot.pose_keys[index])
        robot.pose_marginal = (index, covariance)
        return covariance

    def _landmark_covariance(self, index: int) -> np.ndarray:
        pending = self._pending_landmark_covs.get(index)
        if pending is not None:
            return pending
        covariance = self._marginal(keys.landmark_key(index))
        self._last_landmark_covs[index] = covariance
        return covariance

    def last_landmark_covariance(self, index: int) -> np.ndarray:
        """The landmark's latest known covariance, at no cost: the last marginal iSAM2 gave
        for it, else its first covariance. Factors only add information, so it is at least
        as wide as the current marginal (up to relinearisation)."""
        return self._last_landmark_covs[index]

    # ------------------------------------------------------------------ queries

    @property
    def robot_ids(self) -> list[int]:
        return sorted(self._robots)

    @property
    def update_count(self) -> int:
        """iSAM2 updates so far."""
        return len(self.update_durations_s)

    def keyframe_count(self, robot_id: int) -> int:
        return len(self._robots[robot_id].pose_keys)

    def latest_pose(self, robot_id: int) -> np.ndarray:
        """``[x, y, theta]``: the latest keyframe's estimate composed with the odometry since."""
        robot = self._robots[robot_id]
        return compose(pose2_to_planar(self.pose_estimate(robot.pose_keys[-1])), robot.offset)

    def latest_covariance(self, robot_id: int) -> np.ndarray:
        """World-frame 3x3 covariance of :meth:`latest_pose` (keyframe marginal + offset)."""
        robot = self._robots[robot_id]
        keyframe = pose2_to_planar(self.pose_estimate(robot.pose_keys[-1]))
        cov = _planar_covariance(self.pose_covariance(robot), keyframe[2])
        ja, jb = planar_compose_jacobians(keyframe, robot.offset)
        return ja @ cov @ ja.T + jb @ self.offset_covariance(robot) @ jb.T

    def landmarks(self) -> np.ndarray:
        """(M, 3) landmark positions in the world frame; row i is landmark i."""
        return self._landmark_positions.copy()

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        """Keyframe stamps (N,) and optimised ``[x, y, theta]`` poses (N, 3) of one robot."""
        robot = self._robots[robot_id]
        poses = np.array([pose2_to_planar(self.pose_estimate(k)) for k in robot.pose_keys])
        return np.array(robot.stamps), poses

    def moved_keyframes(self) -> list[tuple[int, int]]:
        """``(robot_id, index)`` of keyframes the last update left more than
        correction_threshold_m from where they were last reported (see _report_moves)."""
        return list(self._moved)
