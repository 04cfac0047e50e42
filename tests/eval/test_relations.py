"""Relations metric (Kümmerle et al. 2009) on hand-made cases with hand-computed errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from acslam.cli import cli
from acslam.errors import DataError
from acslam.eval.relations import (
    read_relations,
    relation_errors,
    relations_from_truth,
    write_relations,
)
from acslam.trajectory import write_tum

# A unit square walked corner to corner, turning left at each corner.
TRUTH = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2], [0.0, 1.0, math.pi]])
STAMPS_S = np.array([10.0, 11.0, 12.0, 13.0])
# Freiburg format, t1 t2 x y z roll pitch yaw: t2's pose in t1's frame. The last relation
# lies after the trajectory's end, so it is not matched.
RELATIONS_TEXT = """\
# hand-made relations of the unit square
10.000000 11.000000 1.0 0.0 0.0 0.0 0.0 0.0
11.000000 12.000000 0.0 1.0 0.0 0.0 0.0 1.5707963267948966
10.000000 13.000000 0.0 1.0 0.0 0.0 0.0 3.141592653589793
12.000000 20.000000 0.0 0.0 0.0 0.0 0.0 0.0
"""


def estimate_off_at_the_end() -> np.ndarray:
    """The truth with the last pose 0.1 m off in y and turned 2 degrees further."""
    estimate = TRUTH.copy()
    estimate[3] += [0.0, 0.1, math.radians(2.0)]
    return estimate


def test_errors_of_a_hand_made_case(tmp_path: Path) -> None:
    path = tmp_path / "square.relations"
    path.write_text(RELATIONS_TEXT)
    relations = read_relations(path)
    assert len(relations) == 4
    exact = relation_errors(STAMPS_S, TRUTH, relations)
    assert exact["translation_mean_m"] == pytest.approx(0.0, abs=1e-12)
    assert exact["rotation_mean_deg"] == pytest.approx(0.0, abs=1e-9)
    scores = relation_errors(STAMPS_S + 0.004, estimate_off_at_the_end(), relations)
    # Only 10 -> 13 sees the last pose: 0.1 m and 2 deg there, 0 on the other two.
    assert (scores["relations"], scores["matched"]) == (4, 3)
    assert scores["matched_fraction"] == 0.75
    assert scores["translation_mean_m"] == pytest.approx(0.1 / 3)
    # Sample std (n - 1) of 0, 0 and 0.1 m: sqrt((2 (0.1/3)^2 + (0.2/3)^2) / 2).
    assert scores["translation_std_m"] == pytest.approx(math.sqrt(0.01 / 3))
    assert scores["translation_mean_square_m2"] == pytest.approx(0.01 / 3)
    assert scores["rotation_mean_deg"] == pytest.approx(2.0 / 3)
    assert scores["rotation_mean_square_deg2"] == pytest.approx(4.0 / 3)


def test_a_stamp_further_than_the_gap_is_not_matched(tmp_path: Path) -> None:
    path = tmp_path / "square.relations"
    path.write_text(RELATIONS_TEXT)
    with pytest.raises(ValueError, match=r"no relation.s times lie within 0\.01 s"):
        relation_errors(STAMPS_S + 0.02, TRUTH, read_relations(path))
    assert relation_errors(STAMPS_S + 0.02, TRUTH, read_relations(path), 0.05)["matched"] == 3
    path.write_text(RELATIONS_TEXT.splitlines()[1] + "\n")
    one = relation_errors(STAMPS_S, TRUTH, read_relations(path))
    assert one["matched"] == 1 and math.isnan(one["translation_std_m"])  # no spread of one


def two_laps() -> tuple[np.ndarray, np.ndarray]:
    """Two laps of a 4 m square at 1 m/s, one pose every 0.1 s."""
    stamps_s = np.round(np.arange(0.0, 32.05, 0.1), 6)
    arc_m = stamps_s % 16.0
    side = (arc_m // 4).astype(int)
    along = arc_m - 4 * side
    corners = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    heading = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2])
    xy = corners[side] + along[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])[side]
    return stamps_s, np.column_stack([xy, heading[side]])


def test_truth_relations_of_two_laps_relate_each_corner_again() -> None:
    """Sampled every second: 32 steps to the next sample, and each second-lap sample
    revisits the first lap's (the last one, at the start, revisits both laps' starts):
    16 + 2 = 18 revisits."""
    stamps_s, truth = two_laps()
    made = relations_from_truth(stamps_s, truth, 1.0, 0.5, 5.0)
    steps = made.second_s - made.first_s
    assert np.count_nonzero(np.isclose(steps, 1.0)) == 32
    revisits = ~np.isclose(steps, 1.0)
    assert np.count_nonzero(revisits) == 18
    assert np.abs(made.relative[revisits]).max() == pytest.approx(0.0, abs=1e-9)
    assert relation_errors(stamps_s, truth, made)["translation_mean_m"] == pytest.approx(0.0)


def test_written_relations_read_back(tmp_path: Path) -> None:
    original = tmp_path / "square.relations"
    original.write_text(RELATIONS_TEXT)
    relations = read_relations(original)
    write_relations(tmp_path / "copy.relations", relations)
    again = read_relations(tmp_path / "copy.relations")
    np.testing.assert_allclose(again.relative, relations.relative, atol=1e-9)
    np.testing.assert_array_equal(again.first_s, relations.first_s)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("10 11 1 0 0 0 0\n", ":1: a relation needs 8 numbers"),
        ("# header\n10 11 1 0 0.2 0 0 0\n", ":2: not planar"),
        ("10 11 1 0 0 0 0 x\n", ":1: not numbers"),
        ("10 11 nan 0 0 0 0 0\n", ":1: a relation's numbers must be finite"),
        ("# nothing\n", "no relations in the file"),
    ],
)
def test_a_bad_relations_file_names_its_line(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "bad.relations"
    path.write_text(text)
    with pytest.raises(DataError, match=problem):
        read_relations(path)


def test_cli_scores_and_writes_json(tmp_path: Path) -> None:
    (tmp_path / "square.relations").write_text(RELATIONS_TEXT)
    write_tum(tmp_path / "est.tum", STAMPS_S, estimate_off_at_the_end())
    result = CliRunner().invoke(
        cli,
        ["eval", "relations", str(tmp_path / "est.tum"), str(tmp_path / "square.relations"),
         "--json", str(tmp_path / "scores.json")],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "translation 0.0333 ± 0.0577 m, rotation 0.667 ± 1.155 deg" in result.output
    assert "over 3 of 4 relations (75.0 % matched)" in result.output
    assert json.loads((tmp_path / "scores.json").read_text())["matched"] == 3
    late = CliRunner().invoke(
        cli,
        ["eval", "relations", str(tmp_path / "est.tum"), str(tmp_path / "square.relations"),
         "--max-gap-s", "0"],
    )  # fmt: skip
    assert late.exit_code == 0  # write_tum keeps the stamps exactly
    write_tum(tmp_path / "late.tum", STAMPS_S + 100.0, TRUTH)
    missed = CliRunner().invoke(
        cli, ["eval", "relations", str(tmp_path / "late.tum"), str(tmp_path / "square.relations")]
    )
    assert missed.exit_code == 1
    assert "late.tum: no relation's times lie within 0.01 s" in missed.output


def test_cli_writes_truth_relations_at_a_runs_keyframes(tmp_path: Path) -> None:
    stamps_s, truth = two_laps()
    write_tum(tmp_path / "truth.tum", stamps_s, truth)
    write_tum(tmp_path / "keyframes.tum", stamps_s[::5], truth[::5])  # every 0.5 s
    out = tmp_path / "made.relations"
    result = CliRunner().invoke(
        cli,
        ["eval", "truth-relations", str(tmp_path / "truth.tum"), str(out),
         "--revisit-radius-m", "0.5", "--at", str(tmp_path / "keyframes.tum")],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert f"50 relations -> {out}" in result.output
    assert set(read_relations(out).first_s) <= set(stamps_s[::5])
    write_tum(tmp_path / "later.tum", stamps_s + 100.0, truth)
    outside = CliRunner().invoke(
        cli,
        ["eval", "truth-relations", str(tmp_path / "truth.tum"), str(out),
         "--at", str(tmp_path / "later.tum")],
    )  # fmt: skip
    assert outside.exit_code == 1
    assert "later.tum: no stamp lies within the time of" in outside.output
