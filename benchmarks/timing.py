"""Timing helper shared by the benchmark scripts (run them from any folder)."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np


def median_ms(run: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``run`` in milliseconds, after one warm-up call (JIT)."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))
