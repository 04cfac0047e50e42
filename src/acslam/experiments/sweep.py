"""Running a sweep: every run of a grid in its own folder, in worker processes.

``DIR/runs/<run-id>/`` is a normal run folder (what ``acslam run`` writes) plus
``spec.json``, the run's definition. A run is finished when its folder has
``metrics.json``, whether it explored everything or not, so re-running a sweep redoes
only the runs that never finished, or that a signal stopped (SIGINT, SIGTERM:
:mod:`acslam.stop`; their folders are emptied first); a folder whose ``spec.json``
disagrees with the grid is an error rather than a silent mix of two sweeps. A run that
cannot write metrics (bad scenario, dead worker) leaves ``failure.json`` with the reason
and is tried again next time. After a signal no further run is started.

Executors run :func:`execute_run` on specs and yield its results in any order; the
process pool here is one implementation, and a cluster one (e.g. Ray) only has to provide
the same ``map``.
"""

from __future__ import annotations

import multiprocessing
import shutil
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol

from acslam import stop
from acslam.errors import AcslamError, ConfigError, WallTimeLimitError
from acslam.experiments.grid import RunSpec
from acslam.files import read_json, write_json, write_text

if TYPE_CHECKING:
    from rich.console import Console

Status = Literal["completed", "incomplete", "failed"]
SPEC_FILE = "spec.json"
FAILURE_FILE = "failure.json"
SWEEP_FILE = "sweep.json"


@dataclass(frozen=True)
class RunResult:
    """How one run ended; ``reason`` is the runner's (``explored``, ``time limit``, ...)."""

    run_id: str
    status: Status
    reason: str
    sim_time_s: float
    wall_time_s: float
    skipped: bool = False


class Executor(Protocol):
    """Runs :func:`execute_run` for each spec; results come back as runs finish."""

    def map(self, specs: Iterable[tuple[RunSpec, Path]]) -> Iterator[RunResult]: ...


def run_dir(out_dir: Path, spec: RunSpec) -> Path:
    return Path(out_dir) / "runs" / spec.run_id


def write_failure(folder: Path, reason: str, wall_time_s: float) -> RunResult:
    """Record a run that wrote no metrics; its folder is named by its run id."""
    folder.mkdir(parents=True, exist_ok=True)
    write_json(folder / FAILURE_FILE, {"reason": reason, "wall_time_s": wall_time_s}, indent=None)
    return RunResult(folder.name, "failed", reason, 0.0, wall_time_s)


def execute_run(spec: RunSpec, folder: Path) -> RunResult:
    """Do one run into ``folder`` (in a worker process); never raises."""
    from acslam.runner import RunHooks, run_exploration
    from acslam.scenario import load_scenario

    started = time.perf_counter()
    stopped: list[str] = []

    def guard(snapshot: object, time_s: float, explored_m2: float) -> None:
        limit = spec.wall_time_limit_s
        if limit is not None and time.perf_counter() - started > limit:
            stopped.append(f"wall-clock limit of {limit:g} s exceeded")
            raise WallTimeLimitError(stopped[0])

    try:
        scenario = load_scenario(spec.scenario, robots=spec.robots, seed=spec.seed)
        scenario = scenario.with_algorithms(spec.planner, spec.allocator)
        if spec.unknown_starts:
            scenario = scenario.with_unknown_starts()
        limit_s = spec.max_time_s or scenario.config.sim.max_time_s
        metrics = run_exploration(scenario, folder, limit_s, hooks=RunHooks(on_progress=guard))
    except Exception as exc:  # a worker must report, not die: the sweep goes on
        reason = str(exc) if isinstance(exc, AcslamError) else f"{type(exc).__name__}: {exc}"
        folder.mkdir(parents=True, exist_ok=True)
        write_text(folder / "error.txt", traceback.format_exc())
        reason = "; then ".join([*stopped, reason])
        return write_failure(folder, reason, time.perf_counter() - started)
    (folder / FAILURE_FILE).unlink(missing_ok=True)
    return RunResult(
        spec.run_id,
        "completed" if metrics["completed"] else "incomplete",
        metrics["reason"],
        metrics["sim_time_s"],
        metrics["wall_time_s"],
    )


class ProcessPoolRunner:
    """Runs specs in ``workers`` spawned processes (fresh interpreters: no forked GTSAM state).

    If a worker dies (segfault, out of memory) the pool breaks; the runs it was holding
    are reported as failed and a new pool carries on with the rest. ``task`` must be a
    module-level function (spawned workers import it). Workers stop their run on a signal
    (:func:`acslam.stop.in_worker`); once the driver has one, no further run starts.
    """

    def __init__(
        self, workers: int, task: Callable[[RunSpec, Path], RunResult] = execute_run
    ) -> None:
        self.workers = workers
        self.task = task

    def map(self, specs: Iterable[tuple[RunSpec, Path]]) -> Iterator[RunResult]:
        pending = list(specs)
        context = multiprocessing.get_context("spawn")
        while pending and stop.requested() is None:
            with ProcessPoolExecutor(
                self.workers, mp_context=context, initializer=stop.in_worker
            ) as pool:
                futures: dict[Future, Path] = {}
                broken = False
                while (pending or futures) and not broken:
                    while pending and len(futures) < self.workers and stop.requested() is None:
                        spec, folder = pending.pop(0)
                        futures[pool.submit(self.task, spec, folder)] = folder
                    if not futures:
                        break
                    done, _ = wait(futures, return_when=FIRST_COMPLETED)
                    for future in done:
                        folder = futures.pop(future)
                        try:
                            result = future.result()
                        except BrokenProcessPool as exc:
                            broken = True
                            result = write_failure(folder, f"worker process died ({exc})", 0)
                        except Exception as exc:  # a task other than execute_run may raise
                            result = write_failure(folder, f"{type(exc).__name__}: {exc}", 0)
                        yield result
                for future, folder in futures.items():  # held by the broken pool
                    future.cancel()
                    yield write_failure(folder, "worker process died (pool broken)", 0.0)


def _check_folder(spec: RunSpec, folder: Path) -> None:
    """A folder made by another grid (other max time, other scenario file) is an error."""
    path = folder / SPEC_FILE
    if path.is_file():
        saved = read_json(path, "run's definition")
        if saved != spec.key():
            raise ConfigError(
                path,
                "",
                f"run {spec.run_id} was made with {saved}, not {spec.key()}: "
                "use another --out folder",
            )


def sweep(
    specs: list[RunSpec],
    out_dir: Path,
    executor: Executor,
    on_result: Callable[[RunSpec, RunResult], None] | None = None,
) -> list[RunResult]:
    """Run every spec not finished yet; returns one result per spec (finished ones skipped)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / SWEEP_FILE, {"runs": [asdict(spec) for spec in specs]}, indent=1)
    by_id = {spec.run_id: spec for spec in specs}
    results: list[RunResult] = []
    todo: list[tuple[RunSpec, Path]] = []
    for spec in specs:
        folder = run_dir(out_dir, spec)
        _check_folder(spec, folder)
        metrics_path = folder / "metrics.json"
        metrics = read_json(metrics_path, "run's metrics") if metrics_path.is_file() else None
        if metrics is not None and metrics["reason"] not in stop.REASONS.values():
            result = RunResult(
                spec.run_id,
                "completed" if metrics["completed"] else "incomplete",
                metrics["reason"],
                metrics["sim_time_s"],
                metrics["wall_time_s"],
                skipped=True,
            )
            results.append(result)
            if on_result is not None:
                on_result(spec, result)
            continue
        if folder.exists():  # unfinished, failed or stopped by a signal: redone from scratch
            shutil.rmtree(folder)
        folder.mkdir(parents=True)
        write_json(folder / SPEC_FILE, spec.key(), indent=None)
        todo.append((spec, folder))
    for result in executor.map(todo):
        results.append(result)
        if on_result is not None:
            on_result(by_id[result.run_id], result)
    return results


def sweep_with_progress(
    specs: list[RunSpec], out_dir: Path, executor: Executor, console: Console
) -> list[RunResult]:
    """:func:`sweep` behind a rich progress bar, one line per run as it ends."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        "{task.fields[tally]}",
        TimeElapsedColumn(),
        console=console,
    ) as progress:
        tally = {"completed": 0, "incomplete": 0, "failed": 0, "skipped": 0}
        task = progress.add_task("runs", total=len(specs), tally="")

        def show(spec: RunSpec, result: RunResult) -> None:
            tally["skipped" if result.skipped else result.status] += 1
            if not result.skipped:
                style = {"completed": "green", "incomplete": "yellow", "failed": "red"}
                progress.console.print(
                    f"[{style[result.status]}]{result.status:>10}[/] {spec.run_id}: "
                    f"{result.reason}, {result.sim_time_s:.1f} s sim in "
                    f"{result.wall_time_s:.1f} s"
                )
            progress.update(
                task, advance=1, tally=", ".join(f"{n} {k}" for k, n in tally.items() if n)
            )

        return sweep(specs, out_dir, executor, show)
