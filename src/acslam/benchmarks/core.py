"""What a benchmark reports, and the timing helpers every benchmark shares.

A time alone says as much about the machine as about the code, so every figure carries a
reference measured in the same process (a NumPy baseline, a reference implementation,
the smallest problem) and the ratio to it; the ratio is what compares across machines.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Figure:
    """One measured figure: ``value`` [unit] and ``ratio`` = value / reference value."""

    group: str
    name: str
    value: float
    unit: str
    reference: str
    reference_value: float
    note: str = ""

    @property
    def ratio(self) -> float:
        return self.value / self.reference_value if self.reference_value else float("nan")


def median_ms(run: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``run`` in milliseconds, after one warm-up call (JIT, caches)."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def timed_s(run: Callable[[], object]) -> float:
    """Wall time of one call in seconds."""
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


def spread_ms(values_ms: np.ndarray, prefix: str = "", empty: float | None = None) -> dict:
    """``<prefix>mean_ms`` and ``<prefix>p95_ms`` of a bucket of timings (``empty`` for
    both when the bucket has none): how a cost reads per graph size."""
    if len(values_ms) == 0:
        return {f"{prefix}mean_ms": empty, f"{prefix}p95_ms": empty}
    return {
        f"{prefix}mean_ms": float(np.mean(values_ms)),
        f"{prefix}p95_ms": float(np.percentile(values_ms, 95)),
    }
