"""Independent searches side by side on threads, up to numba's thread count
(``NUMBA_NUM_THREADS``, by default the machine's cores).

The searches that fill a decision (the robots' A* paths, the travel graph's Dijkstras)
are numba functions that release the GIL, so plain Python threads run them in parallel.
Threads that wait asleep, rather than numba's parallel loops, whose OpenMP workers spin
between loops and so slow everything else where the cores are shared. The calling thread
is one of them. What the tasks compute does not depend on the thread count.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numba

T = TypeVar("T")


def striped(work: Callable[[int, int], None], tasks: int) -> None:
    """Call ``work(first, step)`` once per thread, for as many threads as numba has and
    there are tasks; ``work`` does tasks ``first, first + step, ...`` (the calling thread
    ``first = 0``), so each thread can keep one workspace for all its tasks."""
    threads = max(1, min(numba.config.NUMBA_NUM_THREADS, tasks))
    if threads == 1:
        work(0, 1)
        return
    with ThreadPoolExecutor(threads - 1) as pool:
        others = [pool.submit(work, first, threads) for first in range(1, threads)]
        work(0, threads)
        for other in others:
            other.result()


def mapped(work: Callable[[int], T], count: int) -> list[T]:
    """``[work(0), ..., work(count - 1)]`` on the same threads, each taking the next task
    when it is free: one robot's path can take ten times another's, and fixed stripes
    would leave a thread waiting."""
    results: list[T | None] = [None] * count
    tasks = itertools.count()  # next() on it is atomic under the GIL

    def take(_first: int, _step: int) -> None:
        while (task := next(tasks)) < count:
            results[task] = work(task)

    striped(take, count)
    return results  # type: ignore[return-value]
