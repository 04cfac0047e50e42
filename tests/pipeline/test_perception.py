"""Perception: beams that end on a teammate are dropped once, and the localizer's scan
store keeps exactly what the map gets."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.config import ScanMatchingConfig, SlamConfig
from acslam.messages import LidarScan
from acslam.pipeline.perception import Perception
from acslam.slam.lidar_constraints import LidarConstraints
from acslam.slam.localizer import Isam2Localizer


def test_beams_on_a_teammate_are_dropped_and_the_store_keeps_the_mappable_scan() -> None:
    # Robot 0 at the origin looks along +x; robot 1 stands 2 m ahead of it.
    starts = {0: np.zeros(3), 1: np.array([2.0, 0.0, np.pi])}
    localizer = Isam2Localizer(SlamConfig(), scan_matching=ScanMatchingConfig(), starts=starts)
    perception = Perception(localizer, starts, robot_reach_m=0.25, loop_search_period_s=0.5)
    angles = np.linspace(-0.5, 0.5, 11)  # 0.1 rad apart: the centre beam ends on robot 1
    ranges = np.full(11, 4.0)
    ranges[5] = 1.9  # 0.1 m short of robot 1's centre: within its reach
    ranges[0] = 0.0  # an invalid reading
    scan = LidarScan(0, 0.0, angles, ranges, 8.0)
    (kept,) = perception.localize([scan], now_s=0.0).scans
    assert kept.received is scan
    assert len(kept.mappable.ranges) == 9
    assert not np.isin(kept.mappable.ranges, [0.0, 1.9]).any()
    ((stored, pose),) = localizer.backend.scans.posed()
    assert stored is kept.mappable
    np.testing.assert_allclose(pose, [0.0, 0.0, 0.0])


def test_the_beams_dropped_for_teammates_become_blind_sectors() -> None:
    """Runs of dropped beams, widened by half the 0.1 rad beam spacing, at their nearest
    range; invalid readings are not blind sectors."""
    starts = {0: np.zeros(3), 1: np.array([2.0, 0.0, np.pi]), 2: np.array([0.0, 1.5, 0.0])}
    localizer = Isam2Localizer(SlamConfig(), scan_matching=ScanMatchingConfig(), starts=starts)
    perception = Perception(localizer, starts, robot_reach_m=0.25, loop_search_period_s=0.5)
    angles = np.linspace(-0.5, 1.6, 22)  # 0.1 rad apart; beam 5 at 0, beam 21 at 1.6
    ranges = np.full(22, 4.0)
    ranges[[4, 5, 6]] = [2.05, 1.9, 2.0]  # on robot 1, 2 m ahead
    ranges[[20, 21]] = [1.5, 1.45]  # on robot 2, 1.5 m to the left
    ranges[0] = 0.0
    (kept,) = perception.localize([LidarScan(0, 0.0, angles, ranges, 8.0)], now_s=0.0).scans
    np.testing.assert_allclose(
        kept.blind_sectors, [[-0.15, 0.15, 1.9], [1.45, 1.65, 1.45]], atol=1e-12
    )
    assert len(kept.mappable.ranges) == 22 - 5 - 1


def test_while_loop_pairs_wait_every_cycle_sends_a_job_without_searching(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Searches come every 0.5 s (cycles 3, 8, ...); while found pairs wait to be matched,
    every cycle sends a job for them, without a search; once none wait the period alone
    decides again."""
    starts = {0: np.zeros(3)}
    localizer = Isam2Localizer(SlamConfig(), scan_matching=ScanMatchingConfig(), starts=starts)
    perception = Perception(localizer, starts, robot_reach_m=0.25, loop_search_period_s=0.5)
    waiting = {"pairs": 0}
    monkeypatch.setattr(LidarConstraints, "loops_waiting", property(lambda _: waiting["pairs"]))
    jobs = []

    def loop_matches(slam, search=True, bounded=True):
        jobs.append((cycle, search))
        waiting["pairs"] = {3: 2, 4: 1}.get(cycle, 0)  # what the jobs of cycles 3 and 4 leave
        return lambda: []

    localizer.scan_matcher.loop_matches = loop_matches
    for cycle in range(14):
        perception.localize([], now_s=cycle * 0.1)
    assert jobs == [(3, True), (4, False), (5, False), (8, True), (13, True)]
