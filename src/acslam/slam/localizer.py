"""The ``isam2`` localizer: one iSAM2 graph for the team plus LiDAR scan matching.

Odometry and landmarks go to :class:`~acslam.slam.backend.SlamBackend`; each kept scan
is also matched to its robot's earlier keyframes (and, when the server asks, to nearby
keyframes for loop closures) by :class:`~acslam.slam.lidar_constraints.LidarConstraints`.
"""

from __future__ import annotations

import numpy as np

from acslam.config import ScanMatchingConfig, SlamConfig
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement
from acslam.pipeline.registry import LOCALIZERS
from acslam.slam.backend import SlamBackend
from acslam.slam.lidar_constraints import LidarConstraints

# A loop closure is a large correction: Huber reweighting converges over a few more
# Gauss-Newton steps.
EXTRA_ITERATIONS_AFTER_CLOSURE = 2


@LOCALIZERS.register("isam2", SlamConfig)
class Isam2Localizer:
    """SLAM of the team in one factor graph (thesis §4.4.1-4.4.2)."""

    def __init__(
        self,
        params: SlamConfig,
        *,
        scan_matching: ScanMatchingConfig,
        starts: dict[int, np.ndarray],
    ) -> None:
        self.backend = SlamBackend(params, starts)
        self.scan_matcher = LidarConstraints(scan_matching)

    def add_odometry(self, message: OdometryIncrement) -> None:
        self.backend.add_odometry(message)

    def add_landmarks(self, message: LandmarkObservations) -> None:
        self.backend.add_landmarks(message)

    def add_scan(self, message: LidarScan) -> int | None:
        return self.backend.add_scan(message)

    def match_scan(self, index: int, scan: LidarScan) -> None:
        self.scan_matcher.add_scan(self.backend, index, scan)

    def optimize(self, close_loops: bool) -> None:
        closures = self.scan_matcher.close_loops(self.backend) if close_loops else 0
        self.backend.update(extra_iterations=EXTRA_ITERATIONS_AFTER_CLOSURE if closures else 0)

    def latest_pose(self, robot_id: int) -> np.ndarray:
        return self.backend.latest_pose(robot_id)

    def scan_pose(self, index: int) -> np.ndarray:
        return self.backend.scan_pose(index)

    def moved_scans(self) -> list[int]:
        return self.backend.scans_of_keyframes(self.backend.moved_keyframes())

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        return self.backend.trajectory(robot_id)

    def landmarks(self) -> np.ndarray:
        return self.backend.landmarks()
