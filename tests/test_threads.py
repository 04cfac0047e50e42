"""Work side by side on threads: every task once, in order, on as many threads as numba has."""

from __future__ import annotations

import threading
import time

import numba
import pytest

from acslam import threads


@pytest.mark.parametrize("count", [1, 2, 3])
def test_mapped_work_comes_back_in_order_from_as_many_threads_as_numba_has(
    count: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Seven tasks, each 20 ms asleep: every result in order, run on ``count`` threads,
    the caller's among them."""
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", count)
    workers: set[int] = set()

    def work(task: int) -> int:
        workers.add(threading.get_ident())
        time.sleep(0.02)
        return task * task

    assert threads.mapped(work, 7) == [0, 1, 4, 9, 16, 25, 36]
    assert len(workers) == count
    assert threading.get_ident() in workers


def test_striped_work_covers_every_task_once_and_never_starts_idle_threads(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With 4 threads and 3 tasks, 3 stripes of one task each; with 4 threads and 10
    tasks, stripes 0, 4, 8 / 1, 5, 9 / 2, 6 / 3, 7."""
    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 4)
    for tasks, stripes in [
        (3, {(0,), (1,), (2,)}),
        (10, {(0, 4, 8), (1, 5, 9), (2, 6), (3, 7)}),
    ]:
        assert sorted(_stripes(tasks)) == sorted(stripes)


def _stripes(tasks: int) -> list[tuple[int, ...]]:
    done: list[tuple[int, ...]] = []
    threads.striped(lambda first, step: done.append(tuple(range(first, tasks, step))), tasks)
    return done
