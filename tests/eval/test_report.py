"""The run report reads like a paper's: figures cropped to their content, each with a
numbered caption; every numeric column with its unit; provenance in report and metrics."""

from __future__ import annotations

import json
import re
import subprocess
from datetime import UTC, datetime, timedelta
from html.parser import HTMLParser
from importlib.metadata import version
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from acslam.cli import _progress
from acslam.eval.plotting import plt, save_figure
from acslam.provenance import SOURCE_ROOT

MAX_BLANK_SHARE = 0.25
"""At most this share of a figure's pixel rows, or of its columns, may be blank."""
UNIT = re.compile(r"\[[^\]]+\]")
NUMBER = re.compile(r"^-?\d+(\.\d+)?$")
DASH = "—"


def blank_shares(path: Path) -> tuple[float, float]:
    """Shares of pixel rows and of pixel columns that are all background (white)."""
    with Image.open(path) as image:
        pixels = np.asarray(image.convert("RGB"))
    blank = (pixels == 255).all(axis=2)
    return float(blank.all(axis=1).mean()), float(blank.all(axis=0).mean())


class ReportParser(HTMLParser):
    """Tables (header and rows of cell texts) and figures (caption texts) of a report."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[dict[str, list]] = []
        self.captions: list[str] = []
        self.images = 0
        self._text: list[str] | None = None
        self._row: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list) -> None:
        if tag == "table":
            self.tables.append({"header": [], "rows": []})
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th", "figcaption"):
            self._text = []
        elif tag == "img":
            self.images += 1

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._row is not None and self._text is not None:
            self._row.append("".join(self._text).strip())
        elif tag == "tr" and self._row is not None:
            table = self.tables[-1]
            if not table["header"]:
                table["header"] = self._row
            else:
                table["rows"].append(self._row)
            self._row = None
        elif tag == "figcaption" and self._text is not None:
            self.captions.append("".join(self._text).strip())
        if tag in ("td", "th", "figcaption"):
            self._text = None

    def handle_data(self, data: str) -> None:
        if self._text is not None:
            self._text.append(data)


def parse_report(folder: Path) -> ReportParser:
    parser = ReportParser()
    parser.feed((folder / "report.html").read_text(encoding="utf-8"))
    return parser


def test_the_blank_measure_catches_an_uncropped_canvas_and_save_figure_crops(
    tmp_path: Path,
) -> None:
    def corridor_map() -> plt.Figure:
        # A 4:1 map on a square canvas: equal axes fill a quarter of its height.
        fig, ax = plt.subplots(figsize=(6, 6), dpi=80)
        ax.imshow(np.random.default_rng(0).random((50, 200)), extent=(0, 20, 0, 5))
        ax.set_aspect("equal")
        return fig

    fig = corridor_map()
    fig.savefig(tmp_path / "uncropped.png")
    plt.close(fig)
    rows, _ = blank_shares(tmp_path / "uncropped.png")
    assert rows > 0.5  # more than half the canvas is blank paper
    save_figure(corridor_map(), tmp_path / "cropped.png")
    assert max(blank_shares(tmp_path / "cropped.png")) <= MAX_BLANK_SHARE / 2


def test_every_figure_is_cropped_to_its_content(short_run) -> None:
    paths = sorted((short_run.folder / "figures").glob("*.png"))
    assert len(paths) == 8  # trajectories, map, confusion, area, cycle time, 3 robots' maps
    for path in paths:
        rows, cols = blank_shares(path)
        assert rows <= MAX_BLANK_SHARE and cols <= MAX_BLANK_SHARE, (path.name, rows, cols)


def test_every_figure_has_a_numbered_caption(short_run) -> None:
    report = parse_report(short_run.folder)
    stems = {path.stem for path in (short_run.folder / "figures").glob("*.png")}
    assert report.images == len(stems) == len(report.captions)
    for number, caption in enumerate(report.captions, start=1):
        assert caption.startswith(f"Figure {number}. ")
        text = caption.removeprefix(f"Figure {number}. ")
        assert text not in stems and len(text.split()) >= 6, caption


def test_every_numeric_table_column_states_its_unit(short_run) -> None:
    tables = parse_report(short_run.folder).tables
    assert len(tables) == 9
    checked = 0
    for table in tables:
        header, rows = table["header"], table["rows"]
        assert rows and all(len(row) == len(header) for row in rows), header
        for k, name in enumerate(header):
            cells = [row[k] for row in rows]
            if all(NUMBER.match(c) or c == DASH for c in cells):
                assert UNIT.search(name), f"column {name!r} of numbers has no unit"
                checked += 1
    assert checked >= 20


def test_provenance_in_metrics_and_report(short_run) -> None:
    made = json.loads((short_run.folder / "metrics.json").read_text())["provenance"]
    assert made["acslam_version"] == version("acslam")
    head = subprocess.run(
        ["git", "-C", str(SOURCE_ROOT), "rev-parse", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    if head:  # the tests run from a checkout
        assert made["commit"] in (head, f"{head}-dirty")
    else:
        assert made["commit"] == "unknown"
    assert made["command"] == " ".join(short_run.command)
    date = datetime.strptime(made["date_utc"], "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=UTC)
    assert timedelta(0) <= datetime.now(UTC) - date < timedelta(hours=1)
    page = (short_run.folder / "report.html").read_text(encoding="utf-8")
    for value in made.values():
        assert value in page, value


def test_a_stopped_run_shows_robots_still_exploring_as_a_dash(short_run) -> None:
    metrics = json.loads((short_run.folder / "metrics.json").read_text())
    assert metrics["reason"] == "time limit"
    timing = metrics["timing"]
    assert set(timing["per_robot_s"].values()) == {None}
    assert timing["total_s"] is None and timing["gap_s"] is None
    table = parse_report(short_run.folder).tables[0]
    assert table["header"] == ["robot", "exploration time [s]"]
    assert [row[1] for row in table["rows"]] == [DASH] * 5
    assert "still exploring when the run stopped (time limit)" in (
        short_run.folder / "report.html"
    ).read_text(encoding="utf-8")


def test_explored_area_table_matches_metrics(short_run) -> None:
    coverage = json.loads((short_run.folder / "metrics.json").read_text())["coverage"]
    tables = parse_report(short_run.folder).tables
    (explored,) = [t for t in tables if t["header"][0] == "measure" and "area [m²]" in t["header"]]
    areas = [float(row[1]) for row in explored["rows"]]
    team = max((k for k in coverage if "+" in k), key=lambda k: k.count("+"))
    assert areas == pytest.approx(
        [
            coverage["reachable_area_m2"],
            coverage["mapped_reachable_area_m2"],
            coverage["mapped_area_m2"],
            coverage[team]["area_m2"],
        ],
        abs=0.005,
    )
    assert float(explored["rows"][1][2]) == pytest.approx(
        100 * coverage["explored_fraction_of_reachable"], abs=0.005
    )
    # The area figure ends at the team map's mapped area, sampled each simulated second.
    assert coverage["mapped_area_m2"] > coverage["mapped_reachable_area_m2"] > 0


def test_piped_progress_counts_the_frames_still_apart(capsys: pytest.CaptureFixture) -> None:
    """With unknown starts a piped progress line says how many frames are still apart;
    with one team frame (known starts: no frames) it says nothing of frames."""
    apart = SimpleNamespace(frontier_cells=np.zeros((5, 2)), frames=("a", "b", "c"))
    known = SimpleNamespace(frontier_cells=np.zeros((1, 2)), frames=())
    with _progress("run", 100.0) as show:
        show(apart, 10.0, 12.5)
        show(known, 20.0, 13.0)
    first, second = capsys.readouterr().out.splitlines()
    assert first.startswith(
        "run: 10.0 of 100 s simulated (10 %), 12.5 m² mapped, 5 frontier cells, 3 frames, "
    )
    assert re.fullmatch(
        r"run: 20\.0 of 100 s simulated \(20 %\), 13\.0 m² mapped, 1 frontier cell, \d+ s elapsed",
        second,
    )


def test_console_summary_and_piped_progress_have_units(short_run) -> None:
    lines = short_run.stdout.splitlines()
    progress = [line for line in lines if re.search(r"s simulated \(\d+ %\)", line)]
    # Piped: a plain line per tenth of the limit (the hook is called each simulated second).
    assert len(progress) == 6
    assert all(
        re.search(r"[\d.]+ m² mapped, \d+ frontier cells?, \d+ s elapsed$", line)
        for line in progress
    )
    header = next(line for line in lines if "robot" in line and "RMSE" in line)
    for column in ("time [s]", "RMSE [m]", "final error [m]", "yaw RMSE [rad]", "area [m²]"):
        assert column in header
    assert "m² of reachable free area" in short_run.stdout
    waste = json.loads((short_run.folder / "metrics.json").read_text())["waste"]
    assert f"the robots drove {waste['travelled_total_m']:.1f} m (robot_0 " in short_run.stdout
