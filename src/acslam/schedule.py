"""When periodic work is due: the simulator's sensors, the server's map update, replans
and loop-closure searches.

Due times are sums of float periods and step times multiples of a step (or a recording's
stamps); the two differ in the last bits, and a sum one bit above a step's time would put
the work off by a whole step, after which a schedule drifts.
"""

SCHEDULE_TOLERANCE_S = 1e-6
"""A step this close before a due time is on time."""


def is_due(now_s: float, due_s: float) -> bool:
    """Whether work due at ``due_s`` runs in the step at ``now_s``."""
    return now_s >= due_s - SCHEDULE_TOLERANCE_S


class Periodic:
    """Work due every ``period_s``: first ``offset_s`` after the first step it is asked
    about, then a period after each step it ran in."""

    def __init__(self, period_s: float, offset_s: float = 0.0) -> None:
        self.period_s = period_s
        self.offset_s = offset_s
        self._due_s: float | None = None

    def due(self, now_s: float) -> bool:
        """Whether the work runs in the step at ``now_s`` (if so, the next is scheduled)."""
        if self._due_s is None:
            self._due_s = now_s + self.offset_s
        if not is_due(now_s, self._due_s):
            return False
        self._due_s = now_s + self.period_s
        return True
