"""The server cycle against team size and elapsed time: whole runs of one scenario with
1, 3 and 10 robots for the same simulated time.

A cycle that fits the control period with three robots may not with ten, and one that
fits early in a run may not late: each run's cycle is summarized over the whole run and
over its first and last tenth of simulated time, and the one-robot run is the reference
measured in the same process.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from acslam.benchmarks.core import Figure
from acslam.eval.report import TIMING_WINDOW_S, RunRecord, window_p95_ms
from acslam.runner import run_exploration, tenths_p95_ms
from acslam.scenario import load_scenario
from acslam.text import plural

TEAM_SIZES = (1, 3, 10)


def cycle_summary(samples: np.ndarray) -> dict:
    """Of a stage's ``[simulated time s, wall s]`` samples: mean, p95, p99 and max in ms
    over the run, p95 over its first and last tenth of simulated time, and the p95 per
    ``TIMING_WINDOW_S`` of simulated time (``windows_s``, ``window_p95_ms``)."""
    wall_ms = 1000 * samples[:, 1]
    times_s = samples[:, 0]
    first_ms, last_ms = tenths_p95_ms(samples, float(times_s.min()), float(times_s.max()))
    windows_s, p95_ms = window_p95_ms(samples)
    return {
        "mean_ms": float(wall_ms.mean()),
        "p95_ms": float(np.percentile(wall_ms, 95)),
        "p99_ms": float(np.percentile(wall_ms, 99)),
        "max_ms": float(wall_ms.max()),
        "first_tenth_p95_ms": first_ms,
        "last_tenth_p95_ms": last_ms,
        "windows_s": windows_s,
        "window_p95_ms": p95_ms,
    }


def measure_team_scaling(
    scenario: str | Path, max_time_s: float, team_sizes: Sequence[int] = TEAM_SIZES
) -> dict:
    """Run ``scenario`` with each team size for ``max_time_s`` simulated seconds (or until
    explored). Returns ``{"scenario", "max_time_s", "control_period_ms", "teams": [{"robots",
    "sim_time_s", "real_time_factor", "explored_fraction", "cycle": cycle_summary, "stages":
    {stage: p95 ms}}]}``."""
    teams = []
    period_ms = None
    for robots in team_sizes:
        loaded = load_scenario(scenario, robots=robots)
        period_ms = 1000 * loaded.config.algorithms.planning.control_period_s
        with tempfile.TemporaryDirectory() as folder:
            metrics = run_exploration(loaded, Path(folder), max_time_s=max_time_s)
            record = RunRecord.load(Path(folder) / "run.npz")
        timings = dict(zip(record.stage_names.tolist(), record.stage_timings, strict=True))
        teams.append(
            {
                "robots": robots,
                "sim_time_s": metrics["sim_time_s"],
                "real_time_factor": metrics["real_time_factor"],
                "explored_fraction": metrics["coverage"]["explored_fraction_of_reachable"],
                "cycle": cycle_summary(timings.pop("cycle")),
                "stages": {
                    stage: float(1000 * np.percentile(samples[:, 1], 95))
                    for stage, samples in timings.items()
                    if len(samples)
                },
            }
        )
    return {
        "scenario": str(scenario),
        "max_time_s": max_time_s,
        "control_period_ms": period_ms,
        "teams": teams,
    }


def team_figures(result: dict) -> list[Figure]:
    """Per team size: the cycle's p95 against the smallest team's (same process), and the
    p95 of its last tenth of the run against its first tenth."""
    teams = result["teams"]
    base = teams[0]
    period_ms = result["control_period_ms"]
    figures = []
    for team in teams:
        cycle = team["cycle"]
        worst_stage = max(team["stages"], key=team["stages"].get)
        figures.append(
            Figure(
                "team",
                f"server cycle p95, {plural(team['robots'], 'robot')} ({result['scenario']}, "
                f"{team['sim_time_s']:.0f} s)",
                cycle["p95_ms"],
                "ms",
                plural(base["robots"], "robot"),
                base["cycle"]["p95_ms"],
                f"{cycle['p95_ms'] / period_ms:.2f} of the control period; p99 "
                f"{cycle['p99_ms']:.0f}, max {cycle['max_ms']:.0f} ms; slowest stage "
                f"{worst_stage} p95 {team['stages'][worst_stage]:.0f} ms; "
                f"{team['real_time_factor']:.2f}x real time",
            )
        )
        figures.append(
            Figure(
                "team",
                f"server cycle p95, last tenth of the run, {plural(team['robots'], 'robot')}",
                cycle["last_tenth_p95_ms"],
                "ms",
                "first tenth",
                cycle["first_tenth_p95_ms"],
                "ratio > 1: the cycle got dearer as the run went on",
            )
        )
    return figures


def bench_team(quick: bool) -> list[Figure]:
    """The built-in team-scaling world (``dungeon-40``) with 1, 3 and 10 robots."""
    return team_figures(measure_team_scaling("dungeon-40", 15.0 if quick else 120.0))


def plot_team_scaling(result: dict, path: Path) -> Path:
    """The cycle's p95 per ``TIMING_WINDOW_S`` of simulated time, one line per team size."""
    from acslam.eval.plotting import plt, save_figure

    fig, ax = plt.subplots(figsize=(8.0, 3.6))
    for team in result["teams"]:
        cycle = team["cycle"]
        ax.plot(cycle["windows_s"], cycle["window_p95_ms"], label=plural(team["robots"], "robot"))
    period_ms = result["control_period_ms"]
    ax.axhline(period_ms, color="tab:red", ls=":", label=f"control period {period_ms:.0f} ms")
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel(f"cycle p95 per {TIMING_WINDOW_S:.0f} s [ms]")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.set_title(f"Server cycle against team size: {Path(result['scenario']).stem}")
    return save_figure(fig, path)
