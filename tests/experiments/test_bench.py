"""acslam bench: figures carry a same-process reference; bench.json round-trips."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from acslam.benchmarks import GROUPS, write_json
from acslam.benchmarks.core import Figure
from acslam.benchmarks.perception import bench_scan_matching
from acslam.benchmarks.planning import pyastar2d_expansions
from acslam.cli import cli


def test_ratio_is_value_over_reference_and_json_keeps_it(tmp_path: Path) -> None:
    figures = [
        Figure("g", "a", 3.0, "ms", "ref", 1.5),
        Figure("g", "b", 1.0, "ms", "zero ref", 0.0),
    ]
    assert figures[0].ratio == 2.0
    assert math.isnan(figures[1].ratio)
    saved = json.loads(write_json(figures, tmp_path).read_text())
    assert saved["figures"][0]["ratio"] == 2.0
    assert saved["figures"][0]["reference_value"] == 1.5
    assert saved["figures"][1]["ratio"] is None or math.isnan(saved["figures"][1]["ratio"])


def test_scan_matching_figure_is_measured_against_its_reference() -> None:
    figure, nearest, window, everywhere, pinned = bench_scan_matching(quick=True)
    assert figure.value > 0 and figure.reference_value > 0
    assert figure.ratio == pytest.approx(figure.value / figure.reference_value)
    # ICP of 360-beam scans costs far more than building one scan's KD-tree.
    assert figure.ratio > 1
    # The correspondence search is timed against cKDTree on the same points.
    assert nearest.reference == "cKDTree query of the same points"
    assert nearest.value > 0 and nearest.reference_value > 0
    # Branch and bound is timed against the exhaustive search of the same poses, and
    # the benchmark checks that both found the same one.
    assert window.reference == "exhaustive search of the same poses"
    assert window.note.endswith("the same pose found")
    assert everywhere.value > 0 and everywhere.reference_value > 0
    # A merge's questions: the heading table against branch and bound, the same poses.
    assert pinned.reference == "branch and bound per question"
    assert pinned.note.endswith("the same poses")
    assert pinned.value > 0 and pinned.reference_value > 0


@pytest.mark.slow
def test_bench_quick_covers_every_group(tmp_path: Path) -> None:
    result = CliRunner().invoke(cli, ["bench", "--quick", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    figures = json.loads((tmp_path / "bench.json").read_text())["figures"]
    assert {f["group"] for f in figures} == set(GROUPS)
    names = " ".join(f["name"] for f in figures)
    expected_names = (
        "server cycle: slam",
        "EWFD frontier update (",
        "EWFD frontier update mid-exploration",
        "A*",
        "cells expanded per second",
        "FGP joint solve, 8 robots",
        "iSAM2",
        "global match, branch and bound",
    )
    for expected in expected_names:
        assert expected in names
    assert all(f["reference_value"] > 0 for f in figures)


def testpyastar2d_expansions_finds_the_shortest_path_of_its_graph() -> None:
    """The replica counting pyastar2d's expansions searches pyastar2d's graph: entering a
    cell costs its weight, diagonal or not, corners cut. Its goal cost must equal scipy's
    Dijkstra on that graph, built here edge by edge."""
    rng = np.random.default_rng(3)
    rows, cols = 30, 40
    weights = (1.0 + 4.0 * rng.random((rows, cols))).astype(np.float32)
    weights[rng.random((rows, cols)) < 0.2] = np.inf
    weights[0, 0] = weights[rows - 1, cols - 1] = 1.0
    edges = {}
    for r in range(rows):
        for c in range(cols):
            for dr, dc in itertools.product((-1, 0, 1), repeat=2):
                nr, nc = r + dr, c + dc
                inside = 0 <= nr < rows and 0 <= nc < cols
                if (dr, dc) != (0, 0) and inside and np.isfinite(weights[nr, nc]):
                    edges[(r * cols + c, nr * cols + nc)] = float(weights[nr, nc])
    (u, v), w = zip(*edges.keys(), strict=True), list(edges.values())
    graph = csr_matrix((w, (u, v)), shape=(rows * cols, rows * cols))
    exact = dijkstra(graph, indices=0)[rows * cols - 1]
    expanded, cost = pyastar2d_expansions(weights, 0, rows * cols - 1)
    assert cost == pytest.approx(exact, rel=1e-5)
    assert 0 < expanded <= 9 * rows * cols  # each cell pushed at most once per neighbour


def test_cycle_summary_reads_the_run_and_its_first_and_last_tenth() -> None:
    """1,000 cycles over 99.9 s: 10 ms in the first 10 s, 30 ms in the last 10 s, 20 ms
    between. The first and last tenth of simulated time hold exactly those cycles."""
    from acslam.benchmarks.team_scaling import cycle_summary, team_figures

    times_s = np.round(np.arange(1000) * 0.1, 1)
    wall_s = np.where(times_s < 10.0, 0.010, np.where(times_s >= 90.0, 0.030, 0.020))
    summary = cycle_summary(np.column_stack([times_s, wall_s]))
    assert summary["mean_ms"] == pytest.approx(20.0)
    assert summary["max_ms"] == pytest.approx(30.0)
    assert summary["first_tenth_p95_ms"] == pytest.approx(10.0)
    assert summary["last_tenth_p95_ms"] == pytest.approx(30.0)
    assert summary["windows_s"] == [5.0 + 10.0 * k for k in range(10)]
    assert summary["window_p95_ms"] == pytest.approx([10.0] + [20.0] * 8 + [30.0])
    one = dict(summary, p95_ms=8.0)
    result = {
        "scenario": "dungeon-40",
        "control_period_ms": 100.0,
        "teams": [
            {"robots": 1, "sim_time_s": 99.9, "real_time_factor": 3.0, "cycle": one,
             "stages": {"slam": 5.0}},
            {"robots": 3, "sim_time_s": 99.9, "real_time_factor": 2.0, "cycle": summary,
             "stages": {"slam": 12.0, "mapping": 3.0}},
        ],
    }  # fmt: skip
    figures = team_figures(result)
    assert [f.ratio for f in figures] == pytest.approx([1.0, 3.0, summary["p95_ms"] / 8.0, 3.0])
    assert "slowest stage slam p95 12 ms" in figures[2].note
