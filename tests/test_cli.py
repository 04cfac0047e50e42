"""The command line: every subcommand has help; map and scenarios produce their outputs."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from acslam.cli import cli
from acslam.config import builtin_scenario_names
from acslam.worlds.mapio import load_map


@pytest.mark.parametrize(
    "command", [[], ["scenarios"], ["map"], ["run"], ["report"], ["slam"], ["slam", "mrclam"]]
)
def test_every_command_has_help(command: list[str]) -> None:
    result = CliRunner().invoke(cli, [*command, "--help"])
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.output


def test_scenarios_lists_every_builtin_once() -> None:
    result = CliRunner().invoke(cli, ["scenarios"])
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    listed = [line.split()[0] for line in lines]
    assert listed == builtin_scenario_names()


def test_map_writes_ros_map_and_picture(tmp_path: Path) -> None:
    # Through the installed entry point, as a user would call it.
    result = subprocess.run(
        ["acslam", "map", "--scenario", "thesis-exp4", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    cells, spec = load_map(tmp_path / "map.yaml")
    assert spec.shape == (800, 800) and spec.resolution_m == 0.05
    assert set(np.unique(cells).tolist()) == {0, 100}
    with Image.open(tmp_path / "map.png") as picture:
        assert picture.size[0] > 300


def test_unknown_scenario_is_one_line_error() -> None:
    result = subprocess.run(
        ["acslam", "map", "--scenario", "atlantis", "--out", "unused"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.startswith("acslam: error: atlantis: unknown scenario")
    assert "Traceback" not in result.stderr


def test_slam_mrclam_on_a_missing_dataset_is_one_line_error(tmp_path: Path) -> None:
    result = subprocess.run(
        ["acslam", "slam", "mrclam", str(tmp_path / "none"), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.startswith("acslam: error: ")
    assert "Barcodes.dat: file not found" in result.stderr
    assert "Traceback" not in result.stderr
