"""Scenario validation: every bad config gets one error naming the file and the field."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from acslam.config import builtin_scenario_names, load_scenario_config
from acslam.errors import ConfigError
from acslam.scenario import load_scenario

# A valid scenario: a thesis world with explicit starts in its start area.
BASE = """\
name: test
seed: 3
world:
  generator: thesis
  experiment: 1
robots:
  count: 2
"""

# (yaml text, expected field path in the message, expected words of the problem)
BAD_CONFIGS = {
    "unknown top-level key": (BASE + "colour: red\n", ": colour:", "Extra inputs"),
    "unknown nested key": (
        BASE + "sensors:\n  lidar:\n    rnage_max_m: 5\n",
        ": sensors.lidar.rnage_max_m:",
        "Extra inputs",
    ),
    "wrong type": (
        BASE.replace("count: 2", "count: 2\n  radius_m: big"),
        ": robots.radius_m:",
        "number",
    ),
    "rate zero": (
        BASE + "sensors:\n  lidar:\n    rate_hz: 0\n",
        ": sensors.lidar.rate_hz:",
        "greater than 0",
    ),
    "negative rate": (
        BASE + "sensors:\n  odometry:\n    rate_hz: -5\n",
        ": sensors.odometry.rate_hz:",
        "greater than 0",
    ),
    "resolution zero": (
        BASE.replace("experiment: 1", "experiment: 1\n  resolution_m: 0"),
        ": world.resolution_m:",
        "greater than 0",
    ),
    "unknown generator": (
        BASE.replace("generator: thesis", "generator: moon"),
        ": world:",
        "moon",
    ),
    "experiment out of range": (
        BASE.replace("experiment: 1", "experiment: 7"),
        ": world.experiment:",
        "less than or equal to 5",
    ),
    "missing world": ("name: test\nseed: 1\n", ": world:", "required"),
    "negative seed": (BASE.replace("seed: 3", "seed: -1"), ": seed:", "greater than or equal to 0"),
    "NaN noise": (
        BASE + "sensors:\n  camera:\n    noise_std_m: .nan\n",
        ": sensors.camera.noise_std_m:",
        "finite",
    ),
    "min range above max range": (
        BASE + "sensors:\n  lidar:\n    range_min_m: 9\n",
        ": sensors.lidar:",
        "range_min_m must be below range_max_m",
    ),
    "start pose is a list of two": (
        BASE.replace("count: 2", "starts: [[1.0, 2.0]]"),
        ": robots.starts[0]",
        "",
    ),
    "not a mapping": ("- just\n- a list\n", "", "YAML mapping"),
    "broken YAML": (BASE + "robots: [unclosed\n", "", "invalid YAML at line"),
}


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", sorted(BAD_CONFIGS))
def test_bad_config_names_file_and_field(tmp_path: Path, case: str) -> None:
    text, field, problem = BAD_CONFIGS[case]
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_scenario(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    assert field in message, message
    assert problem in message, message
    assert "\n" not in message


def _thesis_start(index: int) -> tuple[float, float, float]:
    starts = load_scenario("thesis-exp1").starts
    return tuple(float(v) for v in starts[index])


def test_start_pose_in_obstacle(tmp_path: Path) -> None:
    x, y, _ = _thesis_start(0)
    # The grid corner (0.5, 0.5) is solid wall in every thesis world.
    text = BASE.replace("count: 2", f"starts: [[{x}, {y}, 0.0], [0.5, 0.5, 0.0]]")
    with pytest.raises(ConfigError, match=r"robots\.starts\[1\]: start pose \(0\.5, 0\.5\) is in"):
        load_scenario(_write(tmp_path, text))


def test_start_pose_outside_map(tmp_path: Path) -> None:
    x, y, _ = _thesis_start(0)
    text = BASE.replace("count: 2", f"starts: [[{x}, {y}, 0.0], [55.0, 3.0, 0.0]]")
    with pytest.raises(ConfigError, match=r"robots\.starts\[1\]: .*outside the map"):
        load_scenario(_write(tmp_path, text))


def test_overlapping_robots(tmp_path: Path) -> None:
    x, y, _ = _thesis_start(0)
    text = BASE.replace("count: 2", f"starts: [[{x}, {y}, 0.0], [{x + 0.1}, {y}, 1.0]]")
    with pytest.raises(ConfigError, match=r"robots\.starts\[1\]: robot 1 overlaps robot 0"):
        load_scenario(_write(tmp_path, text))


def test_more_robots_than_start_poses(tmp_path: Path) -> None:
    x, y, _ = _thesis_start(0)
    text = BASE.replace("count: 2", f"count: 2\n  starts: [[{x}, {y}, 0.0]]")
    with pytest.raises(ConfigError, match=r"robots\.count: 2 robots requested but only 1"):
        load_scenario(_write(tmp_path, text))
    with pytest.raises(ConfigError, match=r"--robots: 4 robots requested but only 3"):
        load_scenario("thesis-exp2", robots=4)


def test_unknown_builtin_lists_the_builtins() -> None:
    with pytest.raises(ConfigError, match=r"nowhere: unknown scenario .*thesis-exp1"):
        load_scenario_config("nowhere")


def test_missing_scenario_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="scenario file not found"):
        load_scenario_config(tmp_path / "absent.yaml")


def test_robots_option_picks_first_start_poses() -> None:
    three = load_scenario("thesis-exp3")
    one = load_scenario("thesis-exp3", robots=1)
    assert three.robot_count == 3
    assert one.starts.tolist() == three.starts[:1].tolist()


def test_every_builtin_loads() -> None:
    names = builtin_scenario_names()
    assert {"thesis-exp1", "thesis-exp5", "vineyard", "dungeon"} <= set(names)
    for name in names:
        config, source = load_scenario_config(name)
        assert config.name == name, source


def test_relative_world_file_resolves_against_scenario(tmp_path: Path) -> None:
    from acslam.worlds.mapio import save_map, world_cells

    scenario = load_scenario("thesis-exp1")
    save_map(tmp_path / "maps" / "lab", world_cells(scenario.world), scenario.world.spec)
    starts = scenario.starts[:2].tolist()
    text = textwrap.dedent(
        f"""\
        world:
          generator: map_file
          file: maps/lab.yaml
        robots:
          starts: {starts}
        """
    )
    loaded = load_scenario(_write(tmp_path, text))
    assert (loaded.world.occupied == scenario.world.occupied).all()
    assert loaded.robot_count == 2


def test_cli_reports_config_error_in_one_line(tmp_path: Path) -> None:
    path = _write(tmp_path, BASE + "sensors:\n  lidar:\n    rate_hz: 0\n")
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "acslam.cli",
            "map",
            "--scenario",
            str(path),
            "--out",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("acslam: error: ")
    assert "sensors.lidar.rate_hz" in lines[0]
    assert str(path) in lines[0]


EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.yaml"))


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_examples_load(path: Path) -> None:
    config, _ = load_scenario_config(path)
    world_file = getattr(config.world, "file", None)
    if world_file is not None and not world_file.exists():
        pytest.skip(f"shared dataset not found: {world_file}")
    scenario = load_scenario(path)
    assert scenario.robot_count == config.robots.count == len(scenario.starts)
    assert len(scenario.landmarks) > 0
