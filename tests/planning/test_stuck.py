"""Stuck detection fires after the timeout without progress, once per timeout."""

from __future__ import annotations

from acslam.planning.stuck import StuckDetector


def test_progress_keeps_the_detector_quiet() -> None:
    detector = StuckDetector(timeout_s=10.0, min_progress_m=0.1)
    events = [detector.update(t, 20.0 - 0.05 * t) for t in range(0, 300)]
    assert events == [None] * 300 and detector.count == 0


def test_no_progress_fires_once_per_timeout_and_counts() -> None:
    detector = StuckDetector(timeout_s=10.0, min_progress_m=0.1)
    stamps = [0.5 * k for k in range(61)]  # 30 s standing 5 m away, with jitter < 0.1 m
    events = [detector.update(t, 5.0 + 0.04 * (k % 2)) for k, t in enumerate(stamps)]
    fired = [e for e in events if e is not None]
    assert [e.stamp_s for e in fired] == [10.0, 20.0, 30.0]
    assert [e.count for e in fired] == [1, 2, 3] and detector.count == 3
    assert fired[0].distance_to_goal_m == 5.0


def test_reset_restarts_the_clock_but_keeps_the_count() -> None:
    detector = StuckDetector(timeout_s=10.0, min_progress_m=0.1)
    detector.update(0.0, 5.0)
    assert detector.update(10.0, 5.0) is not None
    detector.reset(12.0)
    assert detector.update(12.0, 7.0) is None
    assert detector.update(21.9, 7.0) is None
    event = detector.update(22.0, 7.0)
    assert event is not None and event.count == 2


def test_rebase_accepts_a_longer_replanned_path_without_resetting_the_clock() -> None:
    detector = StuckDetector(timeout_s=10.0, min_progress_m=0.1)
    detector.update(0.0, 0.4)  # a first, short path
    detector.rebase(3.8)  # replanned to the same goal around an obstacle: longer
    events = [detector.update(t, 3.8 - 0.2 * t) for t in range(1, 15)]
    assert events == [None] * 14  # driving the longer path is progress


def test_rebase_keeps_a_trapped_robot_caught() -> None:
    detector = StuckDetector(timeout_s=10.0, min_progress_m=0.1)
    detector.update(0.0, 5.0)
    fired = []
    for t in range(1, 11):
        detector.rebase(5.0 + 0.3 * (t % 2))  # replanned every second, path length jitters
        fired.append(detector.update(float(t), 5.0 + 0.3 * (t % 2)))
    assert [e.stamp_s for e in fired if e is not None] == [10.0]
