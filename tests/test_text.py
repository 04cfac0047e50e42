"""Messages count in good English: "1 robot", "3 robots", never "1 robots"."""

from __future__ import annotations

from pathlib import Path

import pytest

from acslam.errors import ConfigError
from acslam.scenario import load_scenario
from acslam.text import plural


@pytest.mark.parametrize(
    ("count", "noun", "plural_form", "expected"),
    [
        (1, "robot", None, "1 robot"),
        (0, "robot", None, "0 robots"),
        (3, "start pose", None, "3 start poses"),
        (1, "more problem", None, "1 more problem"),
        (2, "frontier cell", None, "2 frontier cells"),
        (1, "process", "processes", "1 process"),
        (4, "process", "processes", "4 processes"),
    ],
)
def test_plural(count: int, noun: str, plural_form: str | None, expected: str) -> None:
    assert plural(count, noun, plural_form) == expected


def test_too_many_robots_for_one_start_pose(tmp_path: Path) -> None:
    path = tmp_path / "one.yaml"
    path.write_text(
        "world: {generator: thesis, experiment: 1}\nrobots: {starts: [[20.0, 17.5, 1.57]]}\n"
    )
    with pytest.raises(ConfigError) as error:
        load_scenario(path, robots=2)
    assert "2 robots requested but only 1 start pose is available" in str(error.value)


def test_one_more_problem(tmp_path: Path) -> None:
    path = tmp_path / "two.yaml"
    path.write_text("seed: -1\nname: [not, a, name]\nworld: {generator: thesis, experiment: 1}\n")
    with pytest.raises(ConfigError) as error:
        load_scenario(path)
    assert str(error.value).endswith("(and 1 more problem)")
