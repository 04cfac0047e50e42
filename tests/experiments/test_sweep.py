"""Sweeps: a tiny grid end to end, resuming, and failures recorded instead of lost."""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner

from acslam.cli import cli
from acslam.errors import ConfigError
from acslam.experiments.grid import RunSpec, expand, parse_grid
from acslam.experiments.sweep import (
    FAILURE_FILE,
    ProcessPoolRunner,
    RunResult,
    execute_run,
    sweep,
)


def test_tiny_grid_end_to_end_then_resume(tmp_path: Path) -> None:
    grid = tmp_path / "tiny.yaml"
    grid.write_text(
        "name: tiny\nmax_time_s: 4\nblocks: [{scenarios: [thesis-exp1], robots: [1, 2]}]\n"
    )
    out = tmp_path / "sweep"
    result = CliRunner().invoke(
        cli, ["experiments", "grid", str(grid), "--out", str(out), "--workers", "2"]
    )
    assert result.exit_code == 0, result.output
    folders = sorted((out / "runs").iterdir())
    assert [f.name for f in folders] == [
        "thesis-exp1-1r-fgp-factor-graph-s0",
        "thesis-exp1-2r-fgp-factor-graph-s0",
    ]
    for folder, robots in zip(folders, (1, 2), strict=True):
        metrics = json.loads((folder / "metrics.json").read_text())
        assert (metrics["robots"], metrics["sim_time_s"], metrics["reason"]) == (
            robots,
            4.0,
            "time limit",
        )
    summary = (out / "summary.md").read_text()
    assert "### Experiment 1: timing evaluation (thesis Table 5.1)" in summary
    assert summary.count("0/1 (1 time limit)") >= 2
    assert (out / "summary.html").read_text().startswith("<!DOCTYPE html>")

    stamps = [(f / "metrics.json").stat().st_mtime_ns for f in folders]
    again = CliRunner().invoke(
        cli, ["experiments", "grid", str(grid), "--out", str(out), "--workers", "2"]
    )
    assert again.exit_code == 0, again.output
    assert "2 skipped" in again.output
    assert [(f / "metrics.json").stat().st_mtime_ns for f in folders] == stamps


class RecordingExecutor:
    """Writes a fake finished run per spec and remembers which specs it was given."""

    def __init__(self) -> None:
        self.seen: list[str] = []

    def map(self, specs: Iterable[tuple[RunSpec, Path]]) -> Iterator[RunResult]:
        for spec, folder in specs:
            self.seen.append(spec.run_id)
            metrics = {
                "completed": True,
                "reason": "explored",
                "sim_time_s": 1.0,
                "wall_time_s": 1.0,
            }
            (folder / "metrics.json").write_text(json.dumps(metrics))
            yield RunResult(spec.run_id, "completed", "explored", 1.0, 1.0)


def small_specs(max_time_s: float = 5.0) -> list[RunSpec]:
    grid = parse_grid({"blocks": [{"scenarios": ["thesis-exp1"], "robots": [1, 2]}]}, "<test>")
    return expand(grid, max_time_s=max_time_s)


def test_resume_hands_only_unfinished_runs_to_the_executor(tmp_path: Path) -> None:
    specs = small_specs()
    first = RecordingExecutor()
    assert [r.skipped for r in sweep(specs, tmp_path, first)] == [False, False]
    assert first.seen == [s.run_id for s in specs]
    second = RecordingExecutor()
    assert [r.skipped for r in sweep(specs, tmp_path, second)] == [True, True]
    assert second.seen == []
    (tmp_path / "runs" / specs[1].run_id / "metrics.json").unlink()
    third = RecordingExecutor()
    sweep(specs, tmp_path, third)
    assert third.seen == [specs[1].run_id]


def test_a_folder_from_another_grid_is_an_error(tmp_path: Path) -> None:
    sweep(small_specs(5.0), tmp_path, RecordingExecutor())
    with pytest.raises(ConfigError, match="use another --out folder"):
        sweep(small_specs(9.0), tmp_path, RecordingExecutor())


def test_bad_scenario_is_a_failure_with_its_reason(tmp_path: Path) -> None:
    scenario = tmp_path / "bad.yaml"
    scenario.write_text(
        "world: {generator: thesis, experiment: 1}\nsensors: {lidar: {rate_hz: -1}}\n"
    )
    spec = RunSpec("bad-1r", str(scenario), 1, "fgp", "factor-graph", 0, 5.0, None, "test")
    result = execute_run(spec, tmp_path / "bad-1r")
    assert result.status == "failed"
    assert "sensors.lidar.rate_hz" in result.reason
    saved = json.loads((tmp_path / "bad-1r" / FAILURE_FILE).read_text())
    assert saved["reason"] == result.reason


def test_wall_time_limit_stops_a_run(tmp_path: Path) -> None:
    spec = RunSpec("slow", "thesis-exp1", 1, "fgp", "factor-graph", 0, 50.0, 1e-6, "test")
    result = execute_run(spec, tmp_path / "slow")
    assert result.status != "completed"
    assert "wall-clock limit of 1e-06 s exceeded" in result.reason
    assert result.sim_time_s < 50.0


def die(spec: RunSpec, folder: Path) -> RunResult:
    """A worker that crashes hard, like a segfault would."""
    os._exit(3)


def test_dead_workers_are_recorded_and_the_sweep_goes_on(tmp_path: Path) -> None:
    specs = small_specs()
    for spec in specs:
        (tmp_path / spec.run_id).mkdir()
    results = list(ProcessPoolRunner(2, task=die).map((s, tmp_path / s.run_id) for s in specs))
    assert sorted(r.run_id for r in results) == sorted(s.run_id for s in specs)
    assert {r.status for r in results} == {"failed"}
    assert all("worker process died" in r.reason for r in results)
    for spec in specs:
        assert "worker process died" in (tmp_path / spec.run_id / FAILURE_FILE).read_text()


@pytest.mark.parametrize(
    "command", [["experiments"], ["experiments", "thesis"], ["experiments", "grid"], ["bench"]]
)
def test_commands_have_help(command: list[str]) -> None:
    result = CliRunner().invoke(cli, [*command, "--help"])
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.output


def test_bad_grid_file_stops_before_any_run(tmp_path: Path) -> None:
    grid = tmp_path / "grid.yaml"
    grid.write_text("blocks: [{scenarios: [thesis-exp1], robots: [one]}]\n")
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["experiments", "grid", str(grid), "--out", str(out)])
    assert result.exit_code == 1
    assert result.stderr.startswith(f"acslam: error: {grid}: blocks.0.robots.0: ")
    assert not out.exists()
