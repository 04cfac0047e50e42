"""Summary aggregation on fabricated run folders, against hand-computed means and stds."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import pytest

from acslam.errors import DataError
from acslam.experiments import thesis_data
from acslam.experiments.grid import RunSpec, run_id
from acslam.experiments.summary import aggregate, fmt, load_runs, write_summary
from acslam.experiments.sweep import FAILURE_FILE, SWEEP_FILE


def fake_metrics(
    robots: int,
    total_s: float,
    completed: bool = True,
    area_m2: float = 60.0,
    stuck: int = 0,
    rmse_m: float = 0.1,
    cycle_ms: float = 20.0,
    overlap_ratio: float = 0.1,
    aligned_rmse_m: float = 0.04,
) -> dict:
    names = [f"robot_{i}" for i in range(robots)]
    per_robot = {name: total_s - 2.0 * i for i, name in enumerate(names)}
    coverage = {"+".join(names[: k + 1]): {"area_m2": area_m2, "rate": 1.0} for k in range(robots)}
    loc = dict.fromkeys(
        (
            "final_dist_m",
            "mae_m",
            "std_m",
            "final_yaw_rad",
            "mae_yaw_rad",
            "rmse_yaw_rad",
            "std_yaw_rad",
        ),
        0.05,
    )
    return {
        "completed": completed,
        "reason": "explored" if completed else "time limit",
        "sim_time_s": total_s,
        "wall_time_s": total_s / 2,
        "real_time_factor": 2.0,
        "timing": {"per_robot_s": per_robot, "total_s": total_s, "gap_s": 2.0 * (robots - 1)},
        "localization": {name: {**loc, "rmse_m": rmse_m} for name in names},
        "team_alignment": {
            "aligned_rmse_m": aligned_rmse_m,
            "rotation_rad": 0.01,
            "translation_m": [0.1, 0.0],
            "centroid_shift_m": 0.1,
        },
        "coverage": {
            **coverage,
            "explored_fraction_of_reachable": 0.99,
            "reachable_area_m2": 67.3,
        },
        "mapping": {"accuracy": 0.95, "tpr": 0.9, "tnr": 0.96, "fpr": 0.04, "fnr": 0.1},
        "waste": {
            "overlap_ratio": overlap_ratio,
            "travelled_m": {name: 0.2 * t for name, t in per_robot.items()},
            "travelled_total_m": 0.2 * sum(per_robot.values()),
        },
        "safety": {
            "obstacle_collisions": 0,
            "robot_collisions": 0,
            "min_robot_distance_m": 0.5 if robots > 1 else math.inf,
            "stuck_events": stuck,
        },
        "server_cycle_ms": {
            "mean": cycle_ms,
            "p95": 2 * cycle_ms,
            "slam": {"mean": 5.0, "p95": 9.0},
        },
    }


def make_sweep(tmp_path: Path, runs: list[tuple[tuple, dict | None, str | None]]) -> Path:
    """``runs``: ((scenario, robots, planner, allocator, seed), metrics or None, failure)."""
    specs = []
    for (scenario, robots, planner, allocator, seed), metrics, failure in runs:
        spec = RunSpec(
            run_id(scenario, robots, planner, allocator, seed),
            scenario, robots, planner, allocator, seed, None, None, "test",
        )  # fmt: skip
        specs.append(asdict(spec))
        folder = tmp_path / "runs" / spec.run_id
        folder.mkdir(parents=True)
        if metrics is not None:
            (folder / "metrics.json").write_text(json.dumps(metrics))
        if failure is not None:
            (folder / FAILURE_FILE).write_text(json.dumps({"reason": failure}))
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"runs": specs}))
    return tmp_path


def test_aggregate_is_mean_and_sample_std() -> None:
    stat = aggregate([150.0, 160.0, 170.0, None, math.nan])
    assert (stat.mean, stat.std, stat.n) == (160.0, 10.0, 3)
    assert fmt(stat) == "160.0 ± 10.0"
    single = aggregate([0.25])
    assert single.n == 1 and math.isnan(single.std)
    assert fmt(single, 2, 100) == "25.00"
    assert aggregate([]) is None and fmt(None) == "—"


@pytest.fixture
def sweep_dir(tmp_path: Path) -> Path:
    exp1 = ("thesis-exp1", 1, "fgp", "factor-graph")
    team = ("thesis-exp1", 2, "fgp", "factor-graph")
    return make_sweep(
        tmp_path,
        [
            (
                (*exp1, 0),
                fake_metrics(1, 150.0, area_m2=60.0, rmse_m=0.10, aligned_rmse_m=0.01),
                None,
            ),
            (
                (*exp1, 1),
                fake_metrics(1, 160.0, area_m2=62.0, rmse_m=0.20, aligned_rmse_m=0.02),
                None,
            ),
            (
                (*exp1, 2),
                fake_metrics(1, 170.0, area_m2=64.0, rmse_m=0.30, aligned_rmse_m=0.03),
                None,
            ),
            ((*team, 0), fake_metrics(2, 80.0, stuck=1), None),
            ((*team, 1), fake_metrics(2, 90.0, stuck=3), None),
            ((*team, 2), fake_metrics(2, 600.0, completed=False, stuck=8), None),
            (("thesis-exp1", 3, "fgp", "factor-graph", 0), None, "worker process died (boom)"),
            (("thesis-exp2", 3, "fgp", "factor-graph", 0), fake_metrics(3, 50.0, stuck=1), None),
            (
                ("thesis-exp2", 3, "fgp", "greedy", 0),
                fake_metrics(3, 70.0, stuck=4, overlap_ratio=0.3),
                None,
            ),
            (
                ("dungeon-40", 1, "fgp", "factor-graph", 0),
                fake_metrics(1, 400.0, cycle_ms=10),
                None,
            ),
            (
                ("dungeon-40", 4, "fgp", "factor-graph", 0),
                fake_metrics(4, 100.0, cycle_ms=30),
                None,
            ),
            (("dungeon-40", 8, "fgp", "factor-graph", 0), None, None),
        ],
    )


def table_row(markdown: str, title: str, first_cell: str) -> list[str]:
    """Cells of the row starting with ``first_cell`` in the table headed ``### title``."""
    section = markdown.split(f"### {title}", 1)[1].split("###", 1)[0]
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0] == first_cell:
            return cells
    raise AssertionError(f"no row {first_cell!r} in {title!r}")


def test_thesis_tables_aggregate_over_seeds(sweep_dir: Path) -> None:
    markdown_path, html_path = write_summary(sweep_dir)
    text = markdown_path.read_text()
    timing = "Experiment 1: timing evaluation (thesis Table 5.1)"
    total = table_row(text, timing, "Total time")
    # Columns: ours 1.1, thesis 1.1, ours 1.2, thesis 1.2, ours 1.3, thesis 1.3.
    assert total[1:3] == ["160.0 ± 10.0", "165.404"]
    # The timed-out seed 2 is left out of the time: mean of 80 and 90, std sqrt(50).
    assert total[3:5] == ["85.0 ± 7.1", "133.751"]
    assert total[5] == "—"  # the only 3-robot run crashed
    speedup = table_row(text, timing, "Speed-up over 1 robot")
    assert speedup[3:5] == [f"{160 / 85:.2f}x", f"{165.404 / 133.751:.2f}x"]
    completed = table_row(text, timing, "Completed runs")
    assert completed[1] == "3/3"
    assert completed[3] == "2/3 (1 time limit)"
    assert completed[5] == "0/1 (1 worker process died (boom))"
    rmse = table_row(
        text, "Experiment 1: position and orientation accuracy (thesis Table 5.2)", "1.1"
    )
    assert rmse[4] == "0.200 ± 0.100"
    localization = text.split("### Experiment 1: position and orientation accuracy", 1)[1]
    team = [row for row in localization.splitlines() if "| 1.1 | team, aligned |" in row]
    assert team[0].split("|")[5].strip() == "0.020 ± 0.010"  # the RMSE column
    coverage = table_row(
        text, "Experiment 1: exploration coverage per robot combination (thesis Table 5.3)", "1.1"
    )
    assert coverage[2:6] == ["62.00 ± 2.00", "100.0 ± 0.0", "64.79", "100.00"]
    accuracy = table_row(
        text, "Experiment 1: mapping accuracy, confusion-based rates (thesis Table 5.4)", "Accuracy"
    )
    assert accuracy[1:] == ["95.0 ± 0.0", "95.0 ± 0.0", "—"]
    waste = "Experiment 1: distance travelled and overlap (not reported by the thesis)"
    # One robot drove 0.2 m per second of its time: 30, 32 and 34 m over the seeds.
    assert table_row(text, waste, "1.1")[1:4] == ["robot_0 (robot_13)", "32.0 ± 2.0", ""]
    # The team's row takes every run, the timed-out one too: 2-robot totals 31.6, 35.6 and 239.6 m.
    team = [row for row in text.split(f"### {waste}")[1].splitlines() if "| 1.2 | team |" in row]
    assert team[0].split("|")[3:5] == [" 102.3 ± 119.0 ", " 10.0 ± 0.0 "]
    assert "worker process died (boom)" in html_path.read_text()


def test_worlds_table_sets_our_layouts_beside_the_thesis_text(sweep_dir: Path) -> None:
    text = write_summary(sweep_dir)[0].read_text()
    title = "Our worlds and the thesis's labs (§5.2)"
    exp1 = table_row(text, title, "exp1")
    assert exp1[2:5] == ["67.3", "1", "(20.0, 17.5), (19.3, 17.5), (20.7, 17.5), facing 90°"]
    assert exp1[5].startswith("a closed start area with a single opening")
    assert exp1[6] == "65.07"  # Table 5.3(c), the team of three
    exp2 = table_row(text, title, "exp2")
    # Our start room has one opening per initial frontier the thesis names.
    assert exp2[3] == "3" and exp2[5].startswith("three initial frontiers")
    assert "predefined starting locations, not given" in text


def test_comparison_scaling_and_every_run_listed(sweep_dir: Path) -> None:
    text = write_summary(sweep_dir)[0].read_text()
    comparison = text.split("### Allocator comparison", 1)[1].split("###", 1)[0]
    rows = [line for line in comparison.splitlines() if line.startswith("| thesis-exp2")]
    assert [r.split("|")[4].strip() for r in rows] == ["factor-graph", "greedy"]
    assert [r.split("|")[6].strip() for r in rows] == ["50.0", "70.0"]
    assert [r.split("|")[8].strip() for r in rows] == ["10.0", "30.0"]  # overlap ratio [%]
    assert [r.split("|")[9].strip() for r in rows] == ["28.8", "40.8"]  # 0.2 m/s of 144, 204 s
    assert [r.split("|")[10].strip() for r in rows] == ["1.0", "4.0"]
    scaling = text.split("### Exploration time, server cycle", 1)[1].split("###", 1)[0]
    eight = [line for line in scaling.splitlines() if line.startswith("| dungeon-40 | 8 |")]
    assert "0/1 (1 no output yet)" in eight[0]
    four = next(line for line in scaling.splitlines() if line.startswith("| dungeon-40 | 4 |"))
    assert "| 4.00x |" in four and "| 30.0 |" in four
    runs = text.split("### Runs", 1)[1]
    assert runs.count("\n| ") == 1 + 12  # the header and every run, failed or not
    assert "| thesis-exp1-3r-fgp-factor-graph-s0 | failed | worker process died (boom) |" in runs
    assert "| dungeon-40-8r-fgp-factor-graph-s0 | not run yet | no output yet |" in runs


def test_not_a_sweep_folder(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no runs found"):
        load_runs(tmp_path)


def test_thesis_numbers_are_consistent_as_transcribed() -> None:
    for experiment, teams in thesis_data.TIMING_S.items():
        for robots, per_robot in teams.items():
            assert len(per_robot) == robots
            timing = thesis_data.thesis_timing(experiment, robots)
            if robots > 1:  # the printed gap is last minus first, to the thesis's rounding
                spread = max(per_robot.values()) - min(per_robot.values())
                assert timing["gap"] == pytest.approx(spread, abs=0.002)
    for teams in thesis_data.COVERAGE.values():
        for robots, rows in teams.items():
            assert len(rows) == 2**robots - 1
            team = max(rows, key=len)
            assert rows[team][1] == 100.0
            # A rate is the combination's area over the team's, to within the thesis's
            # rounding, except one row that the thesis itself prints inconsistently.
            for combo, (area, rate) in rows.items():
                if rows is thesis_data.COVERAGE[1][2] and combo == ("robot_12",):
                    assert 100 * area / rows[team][0] == pytest.approx(91.57, abs=0.01)
                    continue
                assert 100 * area / rows[team][0] == pytest.approx(rate, abs=1.0)
