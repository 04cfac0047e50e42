"""Robot messages into the localizer, and scans made fit for the map: the half of the
server that replays of recorded data run too."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from acslam.geometry import beam_ends
from acslam.messages import (
    LandmarkObservations,
    LidarScan,
    OdometryIncrement,
    RobotMessage,
    RobotSighting,
)
from acslam.pipeline.stages import AssociationResult, Localizer
from acslam.schedule import Periodic


@dataclass(frozen=True)
class KeptScan:
    """A scan the localizer kept: its index, the scan as received, its mappable beams, and
    where teammates blocked its view (:func:`blind_sectors`)."""

    index: int
    received: LidarScan
    mappable: LidarScan
    blind_sectors: np.ndarray


@dataclass(frozen=True)
class Localized:
    """What one batch of messages gave: the kept scans, and what each landmark frame's
    points became (the frame, one result per point)."""

    scans: list[KeptScan]
    landmarks: list[tuple[LandmarkObservations, list[AssociationResult]]]


class Perception:
    """Feeds a localizer and filters each kept scan for mapping.

    A beam that ends within ``robot_reach_m`` of another robot's estimated position is
    dropped before mapping and matching: robots are not walls, and their returns would
    stay in the map after they moved on. Invalid (0) readings are dropped too. The beams
    dropped for teammates become the scan's blind sectors, so that matching does not
    expect this scan to have seen what stood behind them.
    """

    def __init__(
        self,
        localizer: Localizer,
        robot_ids: Iterable[int],
        robot_reach_m: float,
        loop_search_period_s: float,
    ) -> None:
        self.localizer = localizer
        self.robot_ids = list(robot_ids)
        self.robot_reach_m = robot_reach_m
        # Loop searches from half a period after the first batch: the server's map update
        # has the same period from the first cycle, and the two heaviest parts of a cycle
        # (loop matching with iSAM2's extra iterations, and the costmap with frontiers)
        # then fall in different cycles.
        self._loop_searches = Periodic(loop_search_period_s, 0.5 * loop_search_period_s)

    def localize(self, messages: Iterable[RobotMessage], now_s: float) -> Localized:
        """Ingest, match the new scans, optimize (searching for loop closures when due);
        returns the kept scans for the mapper."""
        received: list[tuple[int, LidarScan]] = []
        landmarks = []
        for message in messages:
            if isinstance(message, OdometryIncrement):
                self.localizer.add_odometry(message)
            elif isinstance(message, LandmarkObservations):
                landmarks.append((message, self.localizer.add_landmarks(message)))
            elif isinstance(message, RobotSighting):
                self.localizer.add_sighting(message)
            elif isinstance(message, LidarScan):
                index = self.localizer.add_scan(message)
                if index is not None:
                    received.append((index, message))
        scans = [
            self._kept(index, scan, self.localizer.scan_pose(index)) for index, scan in received
        ]
        for scan in scans:
            self.localizer.match_scan(scan.index, scan.mappable, scan.blind_sectors)
        self.localizer.optimize(close_loops=self._loop_searches.due(now_s))
        return Localized(scans, landmarks)

    def _kept(self, index: int, scan: LidarScan, pose: np.ndarray) -> KeptScan:
        valid = scan.ranges > 0
        keep = valid.copy()
        ends = beam_ends(pose, scan.angles, scan.ranges)
        for j in self.robot_ids:
            if j != scan.robot_id:
                with np.errstate(invalid="ignore"):
                    near = np.linalg.norm(ends - self.localizer.latest_pose(j)[:2], axis=1)
                    keep &= ~(near < self.robot_reach_m)
        sectors = blind_sectors(scan.angles, scan.ranges, valid & ~keep)
        if keep.all():
            return KeptScan(index, scan, scan, sectors)
        mappable = LidarScan(
            scan.robot_id, scan.stamp, scan.angles[keep], scan.ranges[keep], scan.range_max_m
        )
        return KeptScan(index, scan, mappable, sectors)


def blind_sectors(angles_rad: np.ndarray, ranges_m: np.ndarray, blocked: np.ndarray) -> np.ndarray:
    """(K, 3) ``[from_rad, to_rad, range_m]``: each run of consecutive ``blocked`` beams,
    widened by half the beam spacing on either side, and the nearest of their ranges."""
    if not blocked.any():
        return np.zeros((0, 3))
    half_spacing_rad = (
        0.5 * float(np.median(np.abs(np.diff(angles_rad)))) if len(angles_rad) > 1 else 0.0
    )
    edges = np.diff(np.concatenate([[0], blocked.astype(np.int8), [0]]))
    firsts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return np.array(
        [
            [
                float(angles_rad[first:end].min()) - half_spacing_rad,
                float(angles_rad[first:end].max()) + half_spacing_rad,
                float(ranges_m[first:end].min()),
            ]
            for first, end in zip(firsts, ends, strict=True)
        ]
    )
