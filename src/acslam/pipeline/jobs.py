"""Where the server's heavy work runs: in the cycle that scheduled it, or beside the
control loop.

A served run lives on the wall clock: mapping (a correction re-places many scans), a map
update (costmap, frontiers, clusters) or an allocation with its global plans that takes
a second must not hold back the local planner's commands for that second, as Nav2 keeps
its planner and controller servers apart. An in-process run must stay bit-reproducible,
so there a job runs when it is scheduled and its result is used in the same cycle, at
its scheduled simulated time.

Jobs go to a *lane*: the jobs of one lane run one at a time, in the order they were
scheduled, so a lane's stages need no locks (the server's ``map`` lane holds the mapper,
the frontier detector and the clusterer, its ``decisions`` lane the allocator and the
global planner, the localizer's ``loops`` lane loop-closure matching, and with unknown
starts the framed server's ``merges`` lane its looks for a merge). Lanes run side by side,
so a slow allocation does not hold up the map.
Both kinds of jobs give a :class:`~concurrent.futures.Future`; the server takes a result
when ``done()``.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Protocol, TypeVar

T = TypeVar("T")


class Jobs(Protocol):
    """Runs the server's heavy jobs."""

    def submit(self, lane: str, job: Callable[[], T]) -> Future[T]: ...

    def close(self) -> None:
        """Wait for every job scheduled so far (the run is over: the map its products
        are scored on must hold every scan)."""
        ...


class InlineJobs:
    """Each job runs when it is submitted, so its result is ready in the same cycle
    (simulated and replayed runs; an exception leaves from ``submit``)."""

    def submit(self, lane: str, job: Callable[[], T]) -> Future[T]:
        future: Future[T] = Future()
        future.set_result(job())
        return future

    def close(self) -> None:
        return None


class BackgroundJobs:
    """Each lane's jobs run on its own worker thread (served runs): the control cycle
    goes on and takes each result at its first step after the job ended. A job's Python
    parts share the interpreter with the control loop, which gets it back at least every
    ``sys.getswitchinterval()`` (5 ms); NumPy's array loops and the nogil numba kernels
    let go of it while they run."""

    def __init__(self) -> None:
        self._lanes: dict[str, ThreadPoolExecutor] = {}

    def submit(self, lane: str, job: Callable[[], T]) -> Future[T]:
        if lane not in self._lanes:
            self._lanes[lane] = ThreadPoolExecutor(1, thread_name_prefix=f"acslam-{lane}")
        return self._lanes[lane].submit(job)

    def close(self) -> None:
        for pool in self._lanes.values():
            pool.shutdown(wait=True)
