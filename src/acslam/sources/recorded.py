"""A recording as a data source: time-ordered messages played one period at a time."""

from __future__ import annotations

from collections.abc import Sequence

from acslam.messages import RobotMessage
from acslam.pipeline.snapshot import Snapshot


class RecordedSource:
    """Plays ``messages`` (sorted by stamp, stable for equal stamps) in periods of
    ``period_s`` from the first stamp: each :meth:`receive` returns the messages stamped
    before the end of the current period. Commands are ignored (the recording is open
    loop)."""

    def __init__(self, messages: Sequence[RobotMessage], period_s: float) -> None:
        if period_s <= 0:
            raise ValueError("period_s must be positive")
        self.messages = sorted(messages, key=lambda m: m.stamp)
        self.period_s = period_s
        self._next = 0
        self._time_s = self.messages[0].stamp if self.messages else 0.0

    @property
    def time_s(self) -> float:
        return self._time_s

    @property
    def finished(self) -> bool:
        return self._next >= len(self.messages)

    def newly_lost(self) -> list[int]:
        return []

    def receive(self) -> list[RobotMessage]:
        end_s = self._time_s + self.period_s
        start = self._next
        while self._next < len(self.messages) and self.messages[self._next].stamp < end_s:
            self._next += 1
        return list(self.messages[start : self._next])

    def deliver(self, snapshot: Snapshot) -> None:
        """A recording does not listen."""

    def advance(self) -> None:
        self._time_s += self.period_s
