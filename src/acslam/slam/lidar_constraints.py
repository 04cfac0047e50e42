"""LiDAR scans as relative-pose factors of the SLAM graph (thesis §4.4.1).

The first scan of each keyframe is matched (point-to-line ICP,
:mod:`acslam.mapping.scan_matching`) to the first scan of the robot's previous keyframe:
sequential constraints, a laser odometry that makes landmark-poor stretches usable. From
time to time it is also matched to keyframes close in space, of the same robot much
earlier or of another robot: loop closures, which tie trajectories together. Every match
is verified before it enters the graph, and loop closures get a Huber kernel, because a
wrong one would bend the whole map.
"""

from __future__ import annotations

from dataclasses import dataclass

from acslam.config import ScanMatchingConfig
from acslam.geometry import between
from acslam.mapping.scan_matching import (
    Keyframe,
    PreparedScan,
    loop_closure_candidates,
    match_scans,
    prepare_scan,
    verify,
)
from acslam.messages import LidarScan
from acslam.slam.backend import SlamBackend


@dataclass(frozen=True)
class _KeyframeScan:
    scan_index: int
    robot_id: int
    stamp_s: float
    scan: PreparedScan


class LidarConstraints:
    """Adds verified scan-matching factors to a :class:`SlamBackend`."""

    def __init__(self, config: ScanMatchingConfig) -> None:
        self.config = config
        self._entries: list[_KeyframeScan] = []
        self._by_keyframe: dict[tuple[int, int], int] = {}
        self._tried: set[tuple[int, int]] = set()
        self.sequential_added = 0
        self.loops_added = 0
        self.rejected = 0

    def add_scan(self, slam: SlamBackend, scan_index: int, scan: LidarScan) -> None:
        """Keep the first scan of each keyframe and match it to the previous keyframe's."""
        robot_id, keyframe = slam.scan_keyframe(scan_index)
        if (robot_id, keyframe) in self._by_keyframe:
            return
        prepared = prepare_scan(scan.angles, scan.ranges, self.config)
        self._by_keyframe[(robot_id, keyframe)] = len(self._entries)
        self._entries.append(_KeyframeScan(scan_index, robot_id, scan.stamp, prepared))
        previous = self._by_keyframe.get((robot_id, keyframe - 1))
        if previous is not None and self._constrain(
            slam, self._entries[previous], self._entries[-1], robust=False
        ):
            self.sequential_added += 1

    def close_loops(self, slam: SlamBackend) -> int:
        """Match every not yet tried pair of keyframes close in space; returns how many
        closures were added."""
        keyframes = [
            Keyframe(k, e.robot_id, e.stamp_s, slam.scan_pose(e.scan_index), e.scan)
            for k, e in enumerate(self._entries)
        ]
        added = 0
        for pair in loop_closure_candidates(keyframes, self.config):
            if pair in self._tried:
                continue
            self._tried.add(pair)
            if self._constrain(slam, self._entries[pair[0]], self._entries[pair[1]], robust=True):
                added += 1
        self.loops_added += added
        return added

    def _constrain(
        self, slam: SlamBackend, a: _KeyframeScan, b: _KeyframeScan, robust: bool
    ) -> bool:
        guess = between(slam.scan_pose(a.scan_index), slam.scan_pose(b.scan_index))
        result = match_scans(a.scan, b.scan, guess, self.config)
        if not verify(result, guess, self.config):
            self.rejected += 1
            return False
        slam.add_scan_constraint(
            a.scan_index, b.scan_index, result.relative, result.covariance, robust
        )
        return True
