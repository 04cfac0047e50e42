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
