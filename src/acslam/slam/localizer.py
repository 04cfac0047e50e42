"""The ``isam2`` localizer: one iSAM2 graph for the team plus LiDAR scan matching.

Odometry and landmarks go to :class:`~acslam.slam.backend.SlamBackend`; each kept scan
is also matched to its robot's earlier keyframes (and, when the server asks, to nearby
keyframes for loop closures) by :class:`~acslam.slam.lidar_constraints.LidarConstraints`.
The loop-closure matches are a job in the ``loops`` lane of the server's
:mod:`~acslam.pipeline.jobs`: in a served run they run beside the control loop and enter
the graph in the first update after they end.
"""

from __future__ import annotations

from concurrent.futures import Future

import numpy as np

from acslam.config import ScanMatchingConfig, SlamConfig
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, RobotSighting
from acslam.pipeline.jobs import InlineJobs, Jobs
from acslam.pipeline.stages import AssociationResult
from acslam.slam.backend import SlamBackend
from acslam.slam.lidar_constraints import LidarConstraints, LoopMatch

LOOP_LANE = "loops"
"""The jobs' lane of loop-closure matching (see acslam.pipeline.jobs)."""

# A loop closure is a large correction: Huber reweighting converges over a few more
# Gauss-Newton steps; at the end of the data, a few more settle the whole estimate.
EXTRA_ITERATIONS_AFTER_CLOSURE = 2
EXTRA_ITERATIONS_AT_FINISH = 5


class Isam2Localizer:
    """SLAM of the team in one factor graph (thesis §4.4.1-4.4.2)."""

    def __init__(
        self,
        params: SlamConfig,
        *,
        scan_matching: ScanMatchingConfig,
        starts: dict[int, np.ndarray],
        jobs: Jobs | None = None,
        start_sigmas: dict[int, np.ndarray] | None = None,
    ) -> None:
        """``jobs``: where loop-closure matching runs (at once unless given);
        ``start_sigmas``: see :class:`SlamBackend`."""
        self.backend = SlamBackend(params, starts, start_sigmas)
        self.scan_matcher = LidarConstraints(scan_matching)
        self._jobs: Jobs = InlineJobs() if jobs is None else jobs
        self._loop_job: Future[list[LoopMatch]] | None = None

    def add_odometry(self, message: OdometryIncrement) -> None:
        self.backend.add_odometry(message)

    def add_landmarks(self, message: LandmarkObservations) -> list[AssociationResult]:
        return self.backend.add_landmarks(message)

    def add_sighting(self, message: RobotSighting) -> None:
        self.backend.add_robot_observation(
            message.robot_id, message.observed_id, message.stamp, message.point
        )

    def add_scan(self, message: LidarScan) -> int | None:
        return self.backend.add_scan(message)

    def match_scan(self, index: int, scan: LidarScan, blind_sectors: np.ndarray) -> None:
        self.backend.scans.replace(index, scan)
        self.scan_matcher.add_scan(self.backend, index, scan, blind_sectors)

    def optimize(self, close_loops: bool) -> None:
        """Update the graph; searches for loop closures when asked. A job matches at most
        ``loop_matches_per_cycle`` of the pairs found; while some wait, every cycle sends
        the next of them, so a burst is spread over the next cycles."""
        matcher = self.scan_matcher
        if (close_loops or matcher.loops_waiting > 0) and self._loop_job is None:
            self._loop_job = self._jobs.submit(
                LOOP_LANE, matcher.loop_matches(self.backend, search=close_loops)
            )
        closures = 0
        if self._loop_job is not None and self._loop_job.done():
            closures = self.scan_matcher.add_loops(self.backend, self._loop_job.result())
            self._loop_job = None
        self.backend.update(extra_iterations=EXTRA_ITERATIONS_AFTER_CLOSURE if closures else 0)

    def finish(self) -> None:
        if self._loop_job is not None:
            self.scan_matcher.add_loops(self.backend, self._loop_job.result())
            self._loop_job = None
        self.scan_matcher.close_loops(self.backend)
        self.backend.update(extra_iterations=EXTRA_ITERATIONS_AT_FINISH)

    def latest_pose(self, robot_id: int) -> np.ndarray:
        return self.backend.latest_pose(robot_id)

    def scan_pose(self, index: int) -> np.ndarray:
        return self.backend.scans.pose(index)

    def moved_scans(self) -> list[int]:
        return self.backend.scans.of_keyframes(self.backend.moved_keyframes())

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        return self.backend.trajectory(robot_id)

    def landmarks(self) -> np.ndarray:
        return self.backend.landmarks()

    def diagnostics(self) -> dict:
        backend, matcher = self.backend, self.scan_matcher
        updates_ms = 1e3 * np.array(backend.update_durations_s)
        return {
            "keyframes": {str(r): backend.keyframe_count(r) for r in backend.robot_ids},
            "scan_matching": {
                "sequential_accepted": matcher.sequential_added,
                "sequential_rejected": matcher.sequential_rejected,
            },
            "loop_closures": {"accepted": matcher.loops_added, "rejected": matcher.loops_rejected},
            "landmark_association": {
                "dropped_ambiguous": backend.association.dropped_ambiguous,
                "tentative_observations": backend.association.tentative_observations,
                "tentatives_expired": backend.association.expired_tentatives,
            },
            "robot_sightings": backend.association.robot_observations,
            "odometry_calibration": {
                str(r): summary for r, summary in backend.odometry_calibrations().items()
            },
            "skipped_messages": dict(backend.skipped_messages),
            "isam2_update_ms": {
                "count": len(updates_ms),
                "mean": float(updates_ms.mean()) if len(updates_ms) else None,
                "p95": float(np.percentile(updates_ms, 95)) if len(updates_ms) else None,
                "max": float(updates_ms.max()) if len(updates_ms) else None,
            },
        }
