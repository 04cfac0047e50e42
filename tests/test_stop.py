"""SIGINT and SIGTERM end a run at its next step with everything a run writes: metrics
(``completed: false``, reason ``interrupted`` / ``terminated``), figures and report, and
exit 130 / 143. A sweep passes the signal on to its workers, starts no further run, and
redoes a stopped run when resumed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import pytest

from acslam import stop
from acslam.experiments.grid import RunSpec, expand, parse_grid
from acslam.experiments.sweep import SPEC_FILE, ProcessPoolRunner, RunResult, sweep
from acslam.files import write_json
from acslam.runner import RunHooks, run_exploration
from acslam.scenario import load_scenario

STARTUP_TIMEOUT_S = 120.0


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "acslam.cli", *args],
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for(path: Path, process: subprocess.Popen) -> None:
    """Until ``path`` exists: the run has started (config.yaml is its first file)."""
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while not path.exists():
        assert process.poll() is None, process.communicate()[1]
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.1)


def _assert_stopped_run(folder: Path, reason: str) -> dict:
    metrics = json.loads((folder / "metrics.json").read_text())
    assert (metrics["completed"], metrics["reason"]) == (False, reason)
    for name in ("report.html", "run.npz", "map.pgm", "figures/map.png", "figures/confusion.png"):
        assert (folder / name).is_file(), name
    assert "robot_0" in metrics["localization"]
    return metrics


@pytest.mark.parametrize(
    ("signum", "reason", "code"),
    [(signal.SIGTERM, "terminated", 143), (signal.SIGINT, "interrupted", 130)],
    ids=["SIGTERM", "SIGINT"],
)
def test_a_signal_ends_acslam_run_with_its_results(
    tmp_path: Path, signum: int, reason: str, code: int
) -> None:
    out = tmp_path / "run"
    process = _start(["run", "--robots", "1", "--max-time", "600", "--out", str(out)], tmp_path)
    _wait_for(out / "config.yaml", process)
    time.sleep(2.0)  # a few simulated seconds in
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == code, stderr
    assert stderr.splitlines()[-1] == f"acslam: {reason}: the results so far are in {out}"
    metrics = _assert_stopped_run(out, reason)
    assert 0 < metrics["sim_time_s"] < 600


@pytest.mark.parametrize(
    ("signum", "reason"),
    [(signal.SIGTERM, "terminated"), (signal.SIGINT, "interrupted")],
    ids=["SIGTERM", "SIGINT"],
)
def test_the_run_stops_at_the_step_the_signal_came_in(
    tmp_path: Path, signum: int, reason: str
) -> None:
    """The signal arrives from the progress hook at 3 s simulated: the run's last step is
    that one, not one later, not the time limit."""

    def signal_at_3_s(snapshot: object, time_s: float, explored_m2: float) -> None:
        if time_s >= 3.0:
            os.kill(os.getpid(), signum)

    with stop.on_signals() as signals:
        metrics = run_exploration(
            load_scenario("thesis-exp1", robots=2),
            tmp_path,
            max_time_s=60.0,
            hooks=RunHooks(on_progress=signal_at_3_s),
        )
    assert signals.reason == reason and signals.exit_code == 128 + signum
    assert metrics["sim_time_s"] == pytest.approx(3.0)
    _assert_stopped_run(tmp_path, reason)
    assert stop.requested() is None  # handlers and request end with the block


def test_handlers_come_back_and_a_second_ctrl_c_stops_at_once() -> None:
    before = {signum: signal.getsignal(signum) for signum in stop.REASONS}
    with stop.on_signals() as signals:
        os.kill(os.getpid(), signal.SIGTERM)
        os.kill(os.getpid(), signal.SIGTERM)  # a second SIGTERM changes nothing
        assert stop.requested() == "terminated"
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
    assert signals.exit_code == 143
    assert {signum: signal.getsignal(signum) for signum in stop.REASONS} == before


def test_a_worker_keeps_the_first_signal_and_never_raises() -> None:
    before = {signum: signal.getsignal(signum) for signum in stop.REASONS}
    try:
        stop.in_worker()
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.requested() == "interrupted"
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)
        stop._active = None


def test_no_run_starts_after_a_signal(tmp_path: Path) -> None:
    specs = _specs()
    with stop.on_signals():
        os.kill(os.getpid(), signal.SIGTERM)
        started = time.perf_counter()
        results = list(ProcessPoolRunner(2).map((s, tmp_path / s.run_id) for s in specs))
    assert results == [] and time.perf_counter() - started < 1.0


def test_a_signal_stops_a_sweep_and_its_worker(tmp_path: Path) -> None:
    grid = tmp_path / "grid.yaml"
    grid.write_text("blocks: [{scenarios: [thesis-exp1], robots: [1, 2]}]\n")
    out = tmp_path / "sweep"
    process = _start(
        [
            "experiments",
            "grid",
            str(grid),
            "--out",
            str(out),
            "--workers",
            "1",
            "--max-time",
            "600",
        ],
        tmp_path,
    )
    first = out / "runs" / "thesis-exp1-1r-fgp-factor-graph-s0"
    _wait_for(first / "config.yaml", process)
    time.sleep(2.0)
    process.send_signal(signal.SIGTERM)  # to the driver only, as a scheduler sends it
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 143, stderr
    _assert_stopped_run(first, "terminated")
    # The second run never started, and the summary says so.
    second = out / "runs" / "thesis-exp1-2r-fgp-factor-graph-s0"
    assert not (second / "config.yaml").exists()
    assert "not run yet" in (out / "summary.md").read_text()


class FinishingExecutor:
    """Writes a finished run per spec and remembers which specs it was given."""

    def __init__(self) -> None:
        self.seen: list[str] = []

    def map(self, specs: Iterable[tuple[RunSpec, Path]]) -> Iterator[RunResult]:
        for spec, folder in specs:
            self.seen.append(spec.run_id)
            assert sorted(p.name for p in folder.iterdir()) == [SPEC_FILE]
            metrics = {"completed": True, "reason": "explored", "sim_time_s": 1.0}
            write_json(folder / "metrics.json", metrics | {"wall_time_s": 1.0})
            yield RunResult(spec.run_id, "completed", "explored", 1.0, 1.0)


def _specs() -> list[RunSpec]:
    grid = parse_grid({"blocks": [{"scenarios": ["thesis-exp1"], "robots": [1, 2]}]}, "<test>")
    return expand(grid, max_time_s=5.0)


@pytest.mark.parametrize(
    ("reason", "redone"),
    [
        ("terminated", True),
        ("interrupted", True),
        ("explored", False),
        ("time limit", False),
        ("error: the optimiser failed", False),
    ],
)
def test_a_resumed_sweep_redoes_a_run_a_signal_stopped(
    tmp_path: Path, reason: str, redone: bool
) -> None:
    specs = _specs()
    sweep(specs, tmp_path, FinishingExecutor())
    folder = tmp_path / "runs" / specs[0].run_id
    metrics = {"completed": False, "reason": reason, "sim_time_s": 2.0, "wall_time_s": 1.0}
    write_json(folder / "metrics.json", metrics)
    (folder / "trajectories").mkdir()
    (folder / "trajectories" / "robot_0.estimated.tum").write_text("# stopped\n")
    again = FinishingExecutor()
    results = sweep(specs, tmp_path, again)
    assert again.seen == ([specs[0].run_id] if redone else [])
    assert [r.skipped for r in results] == ([True, False] if redone else [True, True])
    assert (folder / "trajectories").exists() is not redone
