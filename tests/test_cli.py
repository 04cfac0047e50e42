"""The command line: every subcommand has help; map and scenarios produce their outputs."""

from __future__ import annotations

import subprocess
from pathlib import Path

import click
import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from acslam.cli import cli
from acslam.config import builtin_scenario_names
from acslam.worlds.mapio import load_map


def _command_paths(group: click.Group = cli, prefix: tuple[str, ...] = ()) -> list[list[str]]:
    """Every command and group of the CLI, as the words that call it."""
    paths = [list(prefix)]
    for name, command in group.commands.items():
        if isinstance(command, click.Group):
            paths += _command_paths(command, (*prefix, name))
        else:
            paths.append([*prefix, name])
    return paths


COMMANDS = _command_paths()


def _help(command: list[str]) -> str:
    # 80 columns, as click lays out help on a usual terminal.
    result = CliRunner().invoke(cli, [*command, "--help"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    return result.output


def _option_help(command: list[str], option: str) -> str:
    """The help text of ``option`` of ``command``, on one line."""
    group: click.Command = cli
    for name in command:
        group = group.commands[name]  # type: ignore[attr-defined]
    (param,) = [p for p in group.params if option in p.opts]
    return " ".join(param.help.split())


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "acslam")
def test_every_command_has_help_with_whole_descriptions(command: list[str]) -> None:
    output = _help(command)
    assert "Usage:" in output
    if "Commands:" in output:
        listing = output.split("Commands:", 1)[1].strip().splitlines()
        assert listing, output
        for line in listing:
            assert not line.rstrip().endswith("..."), f"cut description: {line.strip()}"


@pytest.mark.parametrize(
    ("command", "seconds"),
    [
        (["run"], "Simulated seconds"),
        (["serve"], "Wall-clock seconds"),
        (["robot"], "Seconds on the robot's simulated clock, which runs in real time"),
        (["slam", "mrclam"], "Seconds of the recording's own clock"),
        (["experiments", "thesis"], "Simulated seconds per run"),
        (["experiments", "grid"], "Simulated seconds per run"),
    ],
)
def test_max_time_says_which_seconds(command: list[str], seconds: str) -> None:
    assert _option_help(command, "--max-time").startswith(seconds)


@pytest.mark.parametrize(
    ("command", "option", "says"),
    [
        (["run"], "--drop-rate", "needs --distributed; not with --ros2"),
        (["run"], "--latency-ms", "needs --distributed; not with --ros2"),
        (["robot"], "--drop-rate", "not with --ros2"),
        (["run"], "--viz-out", "needs --viz rerun"),
        (["run"], "--robots", "[default: the scenario's robots.count"),
        (["map"], "--robots", "[default: the scenario's robots.count"),
        (["run"], "--seed", "[default: the scenario's seed]"),
        (["serve"], "--seed", "[default: the scenario's seed]"),
        (["serve"], "--robots", "[default: the scenario's robots"),
    ],
)
def test_options_say_what_they_need_and_default_to(
    command: list[str], option: str, says: str
) -> None:
    assert says in _option_help(command, option)


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


def test_slam_mrclam_unknown_starts_needs_the_sightings(tmp_path: Path) -> None:
    result = subprocess.run(
        ["acslam", "slam", "mrclam", str(tmp_path), "--out", str(tmp_path / "out"),
         "--unknown-starts", "--no-inter-robot"],
        capture_output=True,
        text=True,
        check=False,
    )  # fmt: skip
    assert result.returncode == 2
    assert "--unknown-starts merges the robots' frames by their sightings" in result.stderr
    assert not (tmp_path / "out").exists()
