"""The main job end to end: robots, server and metrics in the closed loop."""

from __future__ import annotations

import json
import subprocess
from itertools import pairwise
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from acslam.cli import cli
from acslam.config import builtin_scenario_names
from acslam.eval.report import RunRecord, rebuild_report
from acslam.runner import run_exploration
from acslam.scenario import load_scenario

METRIC_KEYS = {
    "scenario",
    "robots",
    "seed",
    "planner",
    "allocator",
    "completed",
    "reason",
    "sim_time_s",
    "wall_time_s",
    "real_time_factor",
    "timing",
    "localization",
    "online_localization",
    "team_alignment",
    "coverage",
    "mapping",
    "waste",
    "safety",
    "server_cycle_ms",
    "provenance",
}
TABLE_TITLES = (
    "Timing (Table 5.1)",
    "Localization (Table 5.2)",
    "Coverage per robot combination (Table 5.3)",
    "Explored area",
    "Mapping accuracy (Table 5.4)",
    "Distance and overlap",
    "Safety",
    "Server cycle time",
)


@pytest.mark.parametrize("robots", [1, 2])
def test_small_team_explores_thesis_exp1(tmp_path: Path, robots: int) -> None:
    scenario = load_scenario("thesis-exp1", robots=robots)
    metrics = run_exploration(scenario, tmp_path, max_time_s=400.0)
    assert set(metrics) == METRIC_KEYS
    assert metrics["completed"], metrics["reason"]
    assert metrics["coverage"]["explored_fraction_of_reachable"] >= 0.99
    assert metrics["safety"]["obstacle_collisions"] == 0
    assert metrics["safety"]["robot_collisions"] == 0
    # The thesis's real robots mapped exp1 with 91.9-93.7 % accuracy (Table 5.4).
    assert metrics["mapping"]["accuracy"] >= 0.85
    names = [f"robot_{i}" for i in range(robots)]
    assert list(metrics["localization"]) == names
    assert set(metrics["timing"]["per_robot_s"]) == set(names)
    assert metrics["coverage"]["+".join(names)]["rate"] == pytest.approx(1.0)
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["completed"] is True
    waste = metrics["waste"]
    for name in names:  # the length of the written true path, summed here step by step
        true_xy = np.loadtxt(tmp_path / "trajectories" / f"{name}.groundtruth.tum")[:, 1:3]
        steps_m = [float(np.hypot(*(b - a))) for a, b in pairwise(true_xy)]
        assert waste["travelled_m"][name] == pytest.approx(sum(steps_m), rel=1e-6)
    assert waste["travelled_from"] == "ground truth"
    # The pose the server drove by, at every control step, against the truth there.
    record = RunRecord.load(tmp_path / "run.npz")
    for name, online, true in zip(
        names, record.online_trajectories, record.true_trajectories, strict=True
    ):
        assert len(online) == round(metrics["sim_time_s"] / 0.1) + 1
        gaps_m = np.hypot(
            online[:, 1] - np.interp(online[:, 0], true[:, 0], true[:, 1]),
            online[:, 2] - np.interp(online[:, 0], true[:, 0], true[:, 2]),
        )
        errors = metrics["online_localization"][name]
        assert errors["max_m"] == pytest.approx(gaps_m.max(), rel=1e-9)
        assert errors["rmse_m"] == pytest.approx(np.sqrt(np.mean(gaps_m**2)), rel=1e-9)
        assert 0.0 < errors["max_m"] < 0.5
    assert (waste["overlap_ratio"] == 0.0) if robots == 1 else (0.0 < waste["overlap_ratio"] < 1.0)
    for path in (
        "config.yaml",
        "map.yaml",
        "map.pgm",
        "report.html",
        "run.npz",
        "figures/confusion.png",
        "figures/trajectories.png",
        "figures/explored_area.png",
        "figures/exploration_robot_0.png",
        "trajectories/robot_0.estimated.tum",
        "trajectories/robot_0.groundtruth.tum",
    ):
        assert (tmp_path / path).is_file(), path
    page = (tmp_path / "report.html").read_text()
    for title in TABLE_TITLES:
        assert title in page


def test_time_limit_still_writes_metrics_and_report_rebuilds(tmp_path: Path) -> None:
    metrics = run_exploration(load_scenario("thesis-exp2", robots=2), tmp_path, max_time_s=3.0)
    assert metrics["completed"] is False
    assert metrics["reason"] == "time limit"
    assert json.loads((tmp_path / "metrics.json").read_text())["reason"] == "time limit"
    (tmp_path / "report.html").unlink()
    result = subprocess.run(
        ["acslam", "report", str(tmp_path)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    assert "Timing (Table 5.1)" in (tmp_path / "report.html").read_text()
    # Cycle time: ordered statistics for the cycle and every stage, and their figure.
    cycle = metrics["server_cycle_ms"]
    for stats in [cycle, *(v for v in cycle.values() if isinstance(v, dict))]:
        assert 0 < stats["mean"] <= stats["max"] and stats["p95"] <= stats["p99"] <= stats["max"]
    assert cycle["control_period_ms"] == 100.0 and "slam" in cycle
    assert (tmp_path / "figures" / "cycle_time.png").is_file()
    # A record written before stage timings were kept still rebuilds, without that figure.
    with np.load(tmp_path / "run.npz") as data:
        older = {k: data[k] for k in data if not k.startswith(("stage_", "control_period"))}
    np.savez_compressed(tmp_path / "run.npz", **older)
    (tmp_path / "figures" / "cycle_time.png").unlink()
    rebuild_report(tmp_path)
    assert not (tmp_path / "figures" / "cycle_time.png").exists()


def test_report_of_a_folder_that_is_no_run(tmp_path: Path) -> None:
    result = subprocess.run(
        ["acslam", "report", str(tmp_path)], capture_output=True, text=True, check=False
    )
    assert result.returncode == 1
    assert "metrics.json: not found" in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("name", builtin_scenario_names())
def test_every_builtin_scenario_runs(tmp_path: Path, name: str) -> None:
    result = CliRunner().invoke(
        cli, ["run", "--scenario", name, "--max-time", "1", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["scenario"] == name
    assert metrics["reason"] == "time limit"


@pytest.mark.parametrize("option", [["--planner", "dwa"], ["--allocator", "hungarian"]])
def test_algorithm_options_reach_the_run(tmp_path: Path, option: list[str]) -> None:
    result = CliRunner().invoke(cli, ["run", *option, "--max-time", "1", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    key = "planner" if option[0] == "--planner" else "allocator"
    assert metrics[key] == option[1]
