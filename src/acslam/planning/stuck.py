"""Stuck detection: no progress toward the goal for ``stuck_timeout_s``.

Both local planners can stall in a local minimum (thesis §4.8 notes it for DWA); the
detector only reports it. :mod:`~acslam.planning.recovery` acts on it (back off, replan
around the trap); asking for a new assignment is the caller's choice.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StuckEvent:
    """One report: when, how far from the goal, and the robot's event count so far."""

    stamp_s: float
    distance_to_goal_m: float
    count: int


class StuckDetector:
    """Fires when the best distance to the goal has not improved by ``min_progress_m``
    within ``timeout_s``; after firing it waits another full timeout before firing again.
    A robot waiting at its goal makes no progress either: reset or stop feeding it there.
    """

    def __init__(self, timeout_s: float, min_progress_m: float) -> None:
        self.timeout_s = timeout_s
        self.min_progress_m = min_progress_m
        self.count = 0
        self._best_m: float | None = None
        self._since_s = 0.0

    def reset(self, stamp_s: float) -> None:
        """Start afresh (new goal or after a recovery); the event count is kept."""
        self._best_m = None
        self._since_s = stamp_s

    def rebase(self, distance_to_goal_m: float) -> None:
        """The path to the same goal was replanned and may be longer: progress counts from
        its distance now, while the time since the last real progress keeps running, so a
        robot replanned over and over in a trap (path lengths jittering) is still caught."""
        if self._best_m is not None:
            self._best_m = distance_to_goal_m

    def update(self, stamp_s: float, distance_to_goal_m: float) -> StuckEvent | None:
        """Feed one measurement; returns a :class:`StuckEvent` when the robot is stuck."""
        if self._best_m is None or distance_to_goal_m <= self._best_m - self.min_progress_m:
            self._best_m = distance_to_goal_m
            self._since_s = stamp_s
            return None
        if stamp_s - self._since_s < self.timeout_s:
            return None
        self.count += 1
        self._since_s = stamp_s
        return StuckEvent(stamp_s, distance_to_goal_m, self.count)
