"""Where robot messages come from: the simulator, a recording, or robots on a network.

Every source implements :class:`DataSource`, so the server and the replays never know
which one they are fed by. A closed-loop source (the simulator, live robots) carries the
server's commands back; a recording ignores them.
"""

from __future__ import annotations

import math
import time
from typing import Protocol

from acslam.messages import RobotMessage
from acslam.pipeline.snapshot import Snapshot


class DataSource(Protocol):
    """Messages per control period, on the source's own clock."""

    @property
    def time_s(self) -> float:
        """Simulated, log or wall seconds: the clock the messages are stamped on."""
        ...

    @property
    def finished(self) -> bool:
        """True once a recording has no more messages (never for a live source)."""
        ...

    def newly_lost(self) -> list[int]:
        """Robots that stopped answering since the last call (each reported once)."""
        ...

    def receive(self) -> list[RobotMessage]:
        """The messages that arrived since the last call, in arrival order."""
        ...

    def deliver(self, snapshot: Snapshot) -> None:
        """Send the step's commands (and whatever the robots are told of the server)."""
        ...

    def advance(self) -> None:
        """Let the robots run (or the recording play) until the next period."""
        ...


class LiveSource:
    """Base of the sources of robots on a network: the clock is the wall's, in seconds
    since the source started, the robots never run out, and a step comes every control
    period (a slow step skips a period instead of running late)."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self._started = time.monotonic()

    @property
    def time_s(self) -> float:
        return time.monotonic() - self._started

    @property
    def finished(self) -> bool:
        return False

    def advance(self) -> None:
        elapsed_s = self.time_s
        period_s = self.period_s
        time.sleep(max(0.0, period_s * math.floor(elapsed_s / period_s + 1) - elapsed_s))
