"""Stopping on SIGINT or SIGTERM at the next step, so that what was done is kept.

Ctrl-C sends SIGINT; a job scheduler, ``timeout``, a container stop or a Ray cancel sends
SIGTERM. Either one, while :func:`on_signals` is active, only records the request: the
run loop sees :func:`requested` at its next step and ends the run with that reason
(``interrupted`` or ``terminated``), writing metrics, figures and report as for any other
end, and the command then exits with ``128 + signal number`` (130, 143), as a shell does
for a process a signal ended. A second Ctrl-C stops at once, for a step that hangs.

A sweep's driver passes the signal on to its worker processes, which run the same way
(:func:`in_worker`), and does not start further runs.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from types import FrameType

REASONS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated"}
"""The run's ``reason`` for each signal that stops it."""


@dataclass
class Signals:
    """The first stopping signal received while handlers were set, if any."""

    received: int | None = None

    @property
    def reason(self) -> str | None:
        return None if self.received is None else REASONS[signal.Signals(self.received)]

    @property
    def exit_code(self) -> int | None:
        """``128 + signal number``, as a shell reports a process a signal ended."""
        return None if self.received is None else 128 + self.received


_active: Signals | None = None


def requested() -> str | None:
    """The reason of a stop a signal asked for (``interrupted``, ``terminated``), else None."""
    return None if _active is None else _active.reason


def _record(signum: int, _frame: FrameType | None) -> None:
    if _active is not None and _active.received is None:
        _active.received = signum


def _record_and_pass_on(signum: int, frame: FrameType | None) -> None:
    """The driver's handler: record, pass the signal on to worker processes, and let a
    second Ctrl-C stop at once."""
    if _active is not None and _active.received is not None and signum == signal.SIGINT:
        raise KeyboardInterrupt
    _record(signum, frame)
    for child in multiprocessing.active_children():
        with suppress(ProcessLookupError):
            if child.pid is not None:
                os.kill(child.pid, signum)


@contextmanager
def on_signals() -> Iterator[Signals]:
    """Within the block, SIGINT and SIGTERM ask for a stop instead of ending the process
    (the main thread only; the previous handlers come back after). The value says which
    signal came, after the block too."""
    global _active
    signals = Signals()
    _active = signals
    previous = {signum: signal.signal(signum, _record_and_pass_on) for signum in REASONS}
    try:
        yield signals
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        _active = None


def reclaim() -> None:
    """Set the driver's handlers again after a library replaced them (``ray.init`` makes
    SIGTERM exit the process), if :func:`on_signals` is active."""
    if _active is not None:
        for signum in REASONS:
            signal.signal(signum, _record_and_pass_on)


def in_worker() -> None:
    """A sweep worker's process initializer: a signal (the driver's, passed on, or the
    terminal's to the whole process group) asks its run to stop; repeated ones change
    nothing, so the run always gets to write its results."""
    global _active
    _active = Signals()
    for signum in REASONS:
        signal.signal(signum, _record)
