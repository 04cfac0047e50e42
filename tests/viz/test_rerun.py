"""``--viz rerun`` writes a recording holding the map, costmap, scans, trajectories,
frontiers, allocations and paths of the run."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from acslam.cli import cli

chunk = pytest.importorskip("rerun.chunk")


def test_in_process_run_writes_the_expected_entities(tmp_path: Path) -> None:
    recording = tmp_path / "run.rrd"
    result = CliRunner().invoke(
        cli,
        [
            "run",
            "--robots",
            "2",
            "--max-time",
            "6",
            "--out",
            str(tmp_path / "run"),
            "--viz",
            "rerun",
            "--viz-out",
            str(recording),
        ],
    )
    assert result.exit_code == 0, result.output
    rows: dict[str, int] = {}
    columns: dict[str, set[str]] = {}
    for piece in chunk.RrdReader(recording).store().stream():
        rows[piece.entity_path] = rows.get(piece.entity_path, 0) + piece.num_rows
        names = set(piece.to_record_batch().schema.names)
        columns.setdefault(piece.entity_path, set()).update(names)
    expected = {
        "/world/map": "GridMap:data",
        "/world/costmap": "GridMap:data",
        "/world/frontiers": "Points2D:positions",
        "/world/allocations": "Arrows2D:vectors",
    }
    for robot in ("robot_0", "robot_1"):
        base = f"/world/robots/{robot}"
        expected |= {
            f"{base}/pose": "Points2D:positions",
            f"{base}/scan": "Points2D:positions",
            f"{base}/trajectory": "LineStrips2D:strips",
            f"{base}/path": "LineStrips2D:strips",
        }
    for entity, column in expected.items():
        assert entity in rows, f"{entity} missing; got {sorted(rows)}"
        assert any(name.endswith(column) for name in columns[entity]), columns[entity]
    # 6 s at the 0.1 s control period: one pose per step, maps once a second.
    assert rows["/world/robots/robot_0/pose"] == 60
    assert 5 <= rows["/world/map"] <= 7
    assert rows["/world/robots/robot_1/scan"] >= 10
