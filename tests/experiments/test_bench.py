"""acslam bench: figures carry a same-process reference; bench.json round-trips."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from acslam.benchmarks import GROUPS, write_json
from acslam.benchmarks.core import Figure
from acslam.benchmarks.perception import bench_scan_matching
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
    (figure,) = bench_scan_matching(quick=True)
    assert figure.value > 0 and figure.reference_value > 0
    assert figure.ratio == pytest.approx(figure.value / figure.reference_value)
    # ICP of 360-beam scans costs far more than building one scan's KD-tree.
    assert figure.ratio > 1


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
        "FGP joint solve, 8 robots",
        "iSAM2",
    )
    for expected in expected_names:
        assert expected in names
    assert all(f["reference_value"] > 0 for f in figures)
