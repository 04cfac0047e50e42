"""LiDAR scans attached to keyframes: each scan is stored once, with the keyframe it was
made after and the odometry offset since, so its world pose follows the keyframe's
optimised pose; scan matches become factors between keyframes."""

from __future__ import annotations

from typing import TYPE_CHECKING

import gtsam
import numpy as np

from acslam.geometry import between, compose
from acslam.messages import LidarScan
from acslam.slam import keys
from acslam.slam.factors import planar_to_pose2, pose2_to_planar, rotation_about_z

if TYPE_CHECKING:
    from acslam.slam.backend import SlamBackend


def inverse(pose: np.ndarray) -> np.ndarray:
    """SE(2) inverse of ``[x, y, theta]``."""
    return between(pose, np.zeros(3))


class KeyframeScans:
    """The scans of a :class:`~acslam.slam.backend.SlamBackend`, numbered in arrival order."""

    def __init__(self, backend: SlamBackend) -> None:
        self.backend = backend
        self._scans: list[tuple[LidarScan, int, np.ndarray]] = []
        self._by_keyframe: dict[int, list[int]] = {}
        # Each scan's keyframe key and offset again as arrays (with spare rows), for
        # :meth:`positions`.
        self._keys = np.zeros(64, dtype=np.uint64)
        self._offsets = np.zeros((64, 3))

    def add(self, msg: LidarScan) -> int | None:
        """Store a scan with its robot's latest keyframe and the odometry offset since it.

        Returns the scan's index (for :meth:`pose`), or None if it was skipped.
        """
        robot = self.backend.accept("scan", msg.robot_id, msg.stamp)
        if robot is None:
            return None
        index = len(self._scans)
        keyframe = robot.pose_keys[-1]
        self._scans.append((msg, keyframe, robot.offset.copy()))
        if index == len(self._keys):
            self._keys = np.concatenate([self._keys, np.zeros_like(self._keys)])
            self._offsets = np.concatenate([self._offsets, np.zeros_like(self._offsets)])
        self._keys[index] = keyframe
        self._offsets[index] = robot.offset
        self._by_keyframe.setdefault(keyframe, []).append(index)
        return index

    def replace(self, index: int, scan: LidarScan) -> None:
        """Keep ``scan`` (the same sweep with fewer beams, e.g. those fit for mapping) as
        scan ``index``: what :meth:`posed` returns is then what the map holds."""
        _, keyframe, offset = self._scans[index]
        self._scans[index] = (scan, keyframe, offset)

    def place(self, index: int, reference: int, relative: np.ndarray) -> None:
        """Put scan ``index`` at ``relative`` (``[x, y, theta]``) in the frame of scan
        ``reference`` of the same keyframe, instead of where odometry put it."""
        scan, keyframe, _ = self._scans[index]
        _, reference_keyframe, reference_offset = self._scans[reference]
        if reference_keyframe != keyframe:
            raise ValueError(f"scans {index} and {reference} belong to different keyframes")
        offset = compose(reference_offset, np.asarray(relative, dtype=float))
        self._scans[index] = (scan, keyframe, offset)
        self._offsets[index] = offset

    def pose(self, index: int) -> np.ndarray:
        """Current world pose ``[x, y, theta]`` of stored scan ``index``."""
        _, key, offset = self._scans[index]
        return compose(pose2_to_planar(self.backend.pose_estimate(key)), offset)

    def relative(self, index_a: int, index_b: int) -> np.ndarray:
        """Scan b's sensor pose in scan a's frame, both of one keyframe: from their offsets
        alone, so the same bits whatever the keyframe's estimate (what is built of a
        keyframe's scans can be kept)."""
        _, key_a, offset_a = self._scans[index_a]
        _, key_b, offset_b = self._scans[index_b]
        if key_a != key_b:
            raise ValueError(f"scans {index_a} and {index_b} belong to different keyframes")
        return between(offset_a, offset_b)

    def positions(self, indices: np.ndarray) -> np.ndarray:
        """(k, 2) current world positions of many stored scans at once: :meth:`pose`'s
        ``[x, y]``, vectorised, equal to it up to rounding (see
        :meth:`~acslam.slam.backend.SlamBackend.planar_poses`)."""
        indices = np.asarray(indices, dtype=np.intp)
        keyframes = self.backend.planar_poses(self._keys[indices])
        offsets = self._offsets[indices]
        c, s = np.cos(keyframes[:, 2]), np.sin(keyframes[:, 2])
        return np.column_stack(
            [
                keyframes[:, 0] + c * offsets[:, 0] - s * offsets[:, 1],
                keyframes[:, 1] + s * offsets[:, 0] + c * offsets[:, 1],
            ]
        )

    def keyframe(self, index: int) -> tuple[int, int]:
        """``(robot_id, keyframe_index)`` stored scan ``index`` is attached to."""
        return keys.decode_pose_key(self._scans[index][1])

    def of_keyframes(self, keyframes: list[tuple[int, int]]) -> list[int]:
        """Indices of the scans attached to the ``(robot_id, index)`` keyframes."""
        found: list[int] = []
        for robot_id, index in keyframes:
            found.extend(self._by_keyframe.get(keys.pose_key(robot_id, index), []))
        return found

    def posed(self) -> list[tuple[LidarScan, np.ndarray]]:
        """Every stored scan with its current world pose ``[x, y, theta]``."""
        return [(scan, self.pose(i)) for i, (scan, _, _) in enumerate(self._scans)]

    def add_constraint(
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
        config = self.backend.config
        _, key_a, offset_a = self._scans[index_a]
        _, key_b, offset_b = self._scans[index_b]
        between_keyframes = compose(compose(offset_a, relative), inverse(offset_b))
        rotation = rotation_about_z(offset_a[2])
        planar = rotation @ np.asarray(covariance, dtype=float) @ rotation.T
        noise: gtsam.noiseModel.Base = gtsam.noiseModel.Gaussian.Covariance(planar)
        if robust:
            noise = gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Huber.Create(config.huber_k), noise
            )
        self.backend.add_factor(
            gtsam.BetweenFactorPose2(key_a, key_b, planar_to_pose2(between_keyframes), noise)
        )
