"""Sweeps on a Ray cluster: the same runs as the process pool, as Ray tasks.

Each run executes on whichever node Ray picks, into a scratch folder there; the finished
run folder travels back to the driver as a tar archive inside the task's result and is
unpacked into ``DIR/runs/<run-id>/``. So the nodes need no shared file system, only the
same acslam installation and, for scenario files or datasets given by path, the same
paths. Runs are seeded, so a run's metrics are the same whichever executor ran it.

``address=None`` starts a local Ray instance with ``local_cpus`` CPUs (and stops it at
the end), so ``--workers`` bounds the parallel runs as with the process pool; ``"auto"`` or
``"ray://host:10001"`` joins a running cluster and uses all of it.
"""

from __future__ import annotations

import io
import tarfile
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from acslam import stop
from acslam.errors import AcslamError
from acslam.experiments.grid import RunSpec
from acslam.experiments.sweep import RunResult, execute_run, write_failure


def run_packed(spec: RunSpec) -> tuple[RunResult, bytes]:
    """Run ``spec`` in a scratch folder and return its result and the folder as a tar.

    ``ray.cancel`` interrupts a running task with SIGINT: the run takes it as a stop
    (:func:`acslam.stop.in_worker`) and still returns its results, reason ``interrupted``.
    """
    stop.in_worker()  # Ray reuses worker processes: a fresh record for each run
    with tempfile.TemporaryDirectory(prefix="acslam-ray-") as scratch:
        folder = Path(scratch) / spec.run_id
        result = execute_run(spec, folder)
        buffer = io.BytesIO()
        with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
            archive.add(folder, arcname=".")
        return result, buffer.getvalue()


def unpack(archive_bytes: bytes, folder: Path) -> None:
    """Unpack a run folder made by :func:`run_packed` into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(archive_bytes), mode="r:gz") as archive:
        archive.extractall(folder, filter="data")


SIGNAL_POLL_S = 0.5
"""How often the driver looks for a stopping signal while it waits for Ray."""


class RayRunner:
    """Runs specs as Ray tasks, ``cpus_per_run`` CPUs each; results come as runs finish."""

    def __init__(
        self, address: str | None = None, cpus_per_run: float = 1.0, local_cpus: int = 2
    ) -> None:
        self.address = address
        self.cpus_per_run = cpus_per_run
        self.local_cpus = local_cpus

    def map(self, specs: Iterable[tuple[RunSpec, Path]]) -> Iterator[RunResult]:
        try:
            import ray
        except ImportError as exc:
            raise AcslamError(
                "--executor ray needs Ray: pip install 'acslam[ray]' (or pip install ray)"
            ) from exc
        started_here = not ray.is_initialized()
        if started_here:
            ray.init(
                address=self.address,
                num_cpus=self.local_cpus if self.address is None else None,
                include_dashboard=False,
                log_to_driver=False,
                configure_logging=False,
            )
            stop.reclaim()
        try:
            task = ray.remote(num_cpus=self.cpus_per_run, max_retries=0)(run_packed)
            pending = {task.remote(spec): (spec, folder) for spec, folder in specs}
            cancelled = False
            while pending:
                if stop.requested() is not None and not cancelled:
                    # Running tasks end their run with its results; waiting ones never start.
                    for ref in pending:
                        ray.cancel(ref)
                    cancelled = True
                done, _ = ray.wait(list(pending), num_returns=1, timeout=SIGNAL_POLL_S)
                if not done:
                    continue
                _, folder = pending.pop(done[0])
                try:
                    result, archive = ray.get(done[0])
                except ray.exceptions.TaskCancelledError:
                    continue  # cancelled before it started: nothing ran, a resume runs it
                except ray.exceptions.RayError as exc:  # the task or its node died
                    yield write_failure(folder, f"Ray task failed ({type(exc).__name__})", 0.0)
                    continue
                unpack(archive, folder)
                yield result
        finally:
            if started_here:
                ray.shutdown()
