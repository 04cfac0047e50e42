"""A recording as a data source: time-ordered messages played one period at a time."""

from __future__ import annotations

from collections.abc import Sequence

from acslam.messages import RobotMessage
from acslam.pipeline.snapshot import Snapshot

STAMP_TOLERANCE_S = 5e-7
"""A message stamped this little after a step still belongs to it: more than the ns
rounding of ROS stamps and the float error of UNIX times (~1e-7 s), less than the
microsecond resolution of logs, so a stamp one microsecond late never counts as on time."""


class RecordedSource:
    """Plays ``messages`` (sorted by stamp, stable for equal stamps) as the server receives
    a live team's: the step at time T = ``start_s`` + k ``period_s`` gets every message
    stamped up to T not yet played, as the simulator's robots deliver what they stamped
    in (T - period, T]. ``start_s`` is the recording's first stamp (default: the first
    message's). Commands are ignored (the recording is open loop)."""

    def __init__(
        self, messages: Sequence[RobotMessage], period_s: float, start_s: float | None = None
    ) -> None:
        if period_s <= 0:
            raise ValueError("period_s must be positive")
        self.messages = sorted(messages, key=lambda m: m.stamp)
        self.period_s = period_s
        self._next = 0
        self._step = 0
        first_s = self.messages[0].stamp if self.messages else 0.0
        self._start_s = first_s if start_s is None else start_s

    @property
    def time_s(self) -> float:
        return self._start_s + self._step * self.period_s

    @property
    def finished(self) -> bool:
        return self._next >= len(self.messages)

    def newly_lost(self) -> list[int]:
        return []

    def receive(self) -> list[RobotMessage]:
        end_s = self.time_s + STAMP_TOLERANCE_S
        start = self._next
        while self._next < len(self.messages) and self.messages[self._next].stamp <= end_s:
            self._next += 1
        return list(self.messages[start : self._next])

    def deliver(self, snapshot: Snapshot) -> None:
        """A recording does not listen."""

    def advance(self) -> None:
        self._step += 1
