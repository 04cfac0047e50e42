"""Stages chosen by name: registries, the scenario's stage sections, and plugins from
outside acslam chosen from YAML (in process) and from the CLI (through an entry point)."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from acslam.config import parse_scenario
from acslam.errors import ConfigError, PluginError
from acslam.pipeline.registry import ALLOCATORS, REGISTRIES
from acslam.runner import run_exploration
from acslam.scenario import load_scenario

EXAMPLE_PLUGINS = Path(__file__).resolve().parents[2] / "examples" / "plugins"
EXAMPLE_NAMES = {"allocator": "example-nearest", "local_planner": "example-pursuit"}
WORLD = {"generator": "dungeon"}


@pytest.fixture
def example_plugins() -> Iterator[None]:
    """The example plugin module imported here, and its plugins removed afterwards."""
    sys.path.insert(0, str(EXAMPLE_PLUGINS))
    try:
        importlib.import_module("acslam_example_plugins")
        yield
    finally:
        sys.path.remove(str(EXAMPLE_PLUGINS))
        sys.modules.pop("acslam_example_plugins", None)
        for kind, name in EXAMPLE_NAMES.items():
            REGISTRIES[kind].unregister(name)


def test_registries_hold_the_builtin_plugins_and_name_them_on_a_miss() -> None:
    names = {kind: registry.names() for kind, registry in REGISTRIES.items()}
    assert names == {
        "localizer": ["isam2"],
        "mapper": ["log-odds", "submaps"],
        "frontier_detector": ["ewfd", "naive"],
        "clusterer": ["dbscan"],
        "allocator": ["factor-graph", "greedy", "hungarian", "thesis"],
        "global_planner": ["astar"],
        "local_planner": ["dwa", "fgp"],
    }
    with pytest.raises(PluginError, match=r"unknown allocator 'auction' \(registered: factor-gr"):
        ALLOCATORS.get("auction")


@pytest.mark.parametrize(
    ("algorithms", "field", "problem"),
    [
        ({"allocator": {"name": "auction"}}, "algorithms.allocator", "registered: factor-graph"),
        ({"local_planner": {"name": "fgp", "horizon": 3}}, "algorithms.local_planner.horizon", ""),
        ({"local_planner": {"name": "dwa", "horizon_steps": 9}}, "algorithms.local_planner", ""),
        ({"local_planner": {"name": "fgp", "horizon_steps": 1}}, "algorithms.local_planner", "2"),
        ({"allocator": "hungarian"}, "algorithms.allocator", "mapping"),
    ],
)
def test_a_bad_stage_section_names_the_file_and_field(
    algorithms: dict, field: str, problem: str
) -> None:
    with pytest.raises(ConfigError) as info:
        parse_scenario({"world": WORLD, "algorithms": algorithms}, "lab.yaml")
    assert info.value.source == "lab.yaml"
    assert info.value.field.startswith(field)
    assert problem in info.value.problem


def test_a_stage_section_is_validated_by_its_plugins_params() -> None:
    config = parse_scenario(
        {"world": WORLD, "algorithms": {"local_planner": {"name": "dwa", "v_samples": 5}}}, "x"
    )
    planner = config.algorithms.local_planner
    assert (planner.name, planner.v_samples, planner.omega_samples) == ("dwa", 5, 21)
    # Unset sections are the registry's default plugin with its defaults.
    assert config.algorithms.allocator.name == ALLOCATORS.default == "factor-graph"
    assert config.model_dump(mode="json")["algorithms"]["local_planner"]["v_samples"] == 5


def test_switching_plugins_keeps_only_fields_the_scenario_set() -> None:
    config = parse_scenario(
        {"world": WORLD, "algorithms": {"allocator": {"name": "factor-graph", "alpha": 3.0}}}, "x"
    )
    thesis = config.algorithms.with_stage("allocator", "thesis").allocator
    # alpha was set and carries over; distance_metric was a default and becomes thesis's.
    assert (thesis.name, thesis.alpha, thesis.distance_metric) == (
        "thesis",
        3.0,
        "euclidean-unchecked",
    )
    greedy = config.algorithms.with_stage("allocator", "greedy").allocator
    assert greedy.name == "greedy" and not hasattr(greedy, "alpha")


def test_plugins_chosen_in_yaml_explore(
    example_plugins: None, tiny_scenario: Path, tmp_path: Path
) -> None:
    data = yaml.safe_load(tiny_scenario.read_text())
    data["algorithms"] = {"allocator": {"name": "example-nearest"}}
    path = tiny_scenario.parent / "nearest.yaml"
    path.write_text(yaml.safe_dump(data))
    # A short exploration: 10 s take the team through the door into the second room.
    metrics = run_exploration(load_scenario(path), tmp_path / "run", 10.0)
    assert metrics["allocator"] == "example-nearest" and metrics["planner"] == "fgp"
    assert metrics["coverage"]["explored_fraction_of_reachable"] >= 0.6
    assert metrics["safety"]["obstacle_collisions"] == metrics["safety"]["robot_collisions"] == 0


def test_plugins_registered_by_an_entry_point_are_chosen_on_the_command_line(
    tiny_scenario: Path, tmp_path: Path
) -> None:
    """A package on the path that names the module in the ``acslam.plugins`` group: its
    plugins become CLI choices; one robot runs 10 s with both example plugins."""
    dist = tmp_path / "site" / "acslam_example_plugins-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: acslam-example-plugins\n")
    (dist / "entry_points.txt").write_text("[acslam.plugins]\nexamples = acslam_example_plugins\n")
    out = tmp_path / "run"
    command = [sys.executable, "-m", "acslam.cli", "run", "--scenario", str(tiny_scenario)]
    command += ["--robots", "1", "--max-time", "10", "--out", str(out)]
    command += ["--allocator", "example-nearest", "--planner", "example-pursuit"]
    env = {"PYTHONPATH": f"{dist.parent}:{EXAMPLE_PLUGINS}", "PATH": "/usr/bin:/bin"}
    done = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["allocator"], metrics["planner"]) == ("example-nearest", "example-pursuit")
    resolved = yaml.safe_load((out / "config.yaml").read_text())["algorithms"]
    assert resolved["local_planner"] == {"name": "example-pursuit", "turn_gain_per_s": 1.5}
    truth = np.loadtxt(out / "trajectories" / "robot_0.groundtruth.tum")
    travelled_m = np.linalg.norm(np.diff(truth[:, 1:3], axis=0), axis=1).sum()
    assert travelled_m > 1.0  # at most 0.4 m/s x 10 s = 4 m
    assert metrics["coverage"]["robot_0"]["area_m2"] > 5.0


def test_validating_a_scenario_imports_no_algorithm() -> None:
    """Built-ins are declared with their Params only: checking a scenario, ``--help`` and
    a one-line config error need none of GTSAM, numba or SciPy."""
    heavy = ("gtsam", "numba", "scipy", "cv2", "acslam.exploration.allocation")
    code = (
        "import sys\n"
        "from acslam.config import load_scenario_config\n"
        "for name in ('thesis-exp1', 'vineyard', 'dungeon-40'):\n"
        "    load_scenario_config(name)\n"
        f"print(sorted(m for m in {heavy!r} if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_a_declared_plugin_is_imported_when_first_built() -> None:
    from typing import Literal

    from acslam.exploration.params import GreedyParams

    @ALLOCATORS.declare("acslam.exploration.allocation:GreedyAllocator")
    class LateParams(GreedyParams):
        name: Literal["late-greedy"] = "late-greedy"  # type: ignore[assignment]

    @ALLOCATORS.declare("acslam.exploration.nowhere:Allocator")
    class MissingParams(GreedyParams):
        name: Literal["missing"] = "missing"  # type: ignore[assignment]

    try:
        from acslam.exploration.allocation import GreedyAllocator

        assert ALLOCATORS.get("late-greedy").factory is GreedyAllocator
        with pytest.raises(PluginError, match="allocator 'missing': cannot import"):
            ALLOCATORS.create(MissingParams())
        with pytest.raises(PluginError, match="expected 'module:attribute'"):
            ALLOCATORS.declare("acslam.exploration.allocation")
    finally:
        ALLOCATORS.unregister("late-greedy")
        ALLOCATORS.unregister("missing")
