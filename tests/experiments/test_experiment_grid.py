"""Experiment grids: expansion into runs, the built-ins, and one clear error per bad field."""

from __future__ import annotations

from pathlib import Path

import pytest

from acslam.errors import ConfigError
from acslam.experiments.grid import builtin_grid, check_cells, expand, load_grid_file
from acslam.scenario import load_scenario


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "grid.yaml"
    path.write_text(text)
    return path


def test_blocks_expand_to_unique_runs_with_stable_ids(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
name: small
max_time_s: 30
blocks:
  - scenarios: [thesis-exp1, thesis-exp2]
    robots: [1, 2]
    seeds: 2
  - scenarios: [thesis-exp2]
    robots: [2]
    allocators: [factor-graph, greedy]
    seeds: [1]
""",
    )
    specs = expand(load_grid_file(path))
    ids = [s.run_id for s in specs]
    # 2 x 2 x 2 = 8 from the first block; the second adds only the greedy run.
    assert len(ids) == 9 == len(set(ids))
    assert ids[0] == "thesis-exp1-1r-fgp-factor-graph-s0"
    assert ids[-1] == "thesis-exp2-2r-fgp-greedy-s1"
    assert {s.max_time_s for s in specs} == {30.0}
    # --seeds 3 gives every block seeds 0-2: 2 x 2 x 3 plus the greedy run x 3.
    assert len(expand(load_grid_file(path), max_time_s=5, seeds=3)) == 2 * 2 * 3 + 3
    assert {s.max_time_s for s in expand(load_grid_file(path), max_time_s=5)} == {5.0}


def test_scenario_files_resolve_against_the_grid_file(tmp_path: Path) -> None:
    (tmp_path / "lab.yaml").write_text("name: lab\nworld: {generator: thesis, experiment: 2}\n")
    specs = expand(load_grid_file(write(tmp_path, "blocks: [{scenarios: [lab.yaml]}]")))
    assert [s.run_id for s in specs] == ["lab-3r-fgp-factor-graph-s0"]
    assert specs[0].scenario == str((tmp_path / "lab.yaml").resolve())


@pytest.mark.parametrize(
    ("text", "field", "problem"),
    [
        ("blocks: [{scenarios: [thesis-exp1], robots: [0]}]", "blocks.0.robots.0", "greater"),
        ("blocks: [{scenarios: [thesis-exp1], planner: [fgp]}]", "blocks.0.planner", "Extra"),
        ("blocks: [{scenarios: [thesis-exp1], planners: [astar]}]", "blocks.0.planners.0", "fgp"),
        ("blocks: [{scenarios: [thesis-exp1], seeds: 0}]", "blocks.0.seeds", "at least 1"),
        ("blocks: [{scenarios: [thesis-exp1], robots: [2, 2]}]", "blocks.0.robots", "repeat"),
        ("blocks: [{scenarios: [no-such-place]}]", "blocks.0.scenarios.0", "neither"),
        ("blocks: []", "blocks", "at least 1"),
        ("max_time_s: -1\nblocks: [{scenarios: [thesis-exp1]}]", "max_time_s", "greater"),
    ],
)
def test_bad_grid_names_file_and_field(tmp_path: Path, text: str, field: str, problem: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_grid_file(path)
    assert info.value.source == str(path)
    assert info.value.field == field
    assert problem in info.value.problem


def test_unreadable_grid_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_grid_file(tmp_path / "missing.yaml")
    with pytest.raises(ConfigError, match="invalid YAML at line 2"):
        load_grid_file(write(tmp_path, "blocks: [\n"))
    with pytest.raises(ConfigError, match="mapping"):
        load_grid_file(write(tmp_path, "- a\n- b\n"))


def test_thesis_grid_is_chapter_5_plus_comparisons() -> None:
    specs = expand(builtin_grid("thesis"), seeds=3)
    cells = {(s.scenario, s.robots, s.planner, s.allocator) for s in specs}
    # exp1-4 x 1-3 robots, exp5 x 3 robots, 3 more allocators and dwa on exp2 and exp3.
    assert len(cells) == 4 * 3 + 1 + 2 * 3 + 2
    assert len(specs) == 3 * len(cells)
    assert ("thesis-exp5", 3, "fgp", "factor-graph") in cells
    assert not any(s.scenario == "thesis-exp5" and s.robots < 3 for s in specs)


def test_scaling_grid_scenarios_have_eight_start_poses() -> None:
    specs = expand(builtin_grid("scaling"))
    assert {(s.scenario, s.robots) for s in specs} == {
        (name, robots) for name in ("dungeon-40", "vineyard-40") for robots in (1, 2, 4, 8)
    }
    for name in ("dungeon-40", "vineyard-40"):
        assert load_scenario(name, robots=8).robot_count == 8


def test_unknown_builtin_grid() -> None:
    with pytest.raises(ConfigError, match="built-ins: thesis, scaling"):
        builtin_grid("chapter6")


def test_example_allocator_grid_is_every_thesis_experiment_with_both_allocators() -> None:
    path = Path(__file__).resolve().parents[2] / "examples" / "grids" / "allocators-10-seeds.yaml"
    grid = load_grid_file(path)
    check_cells(grid, str(path))
    specs = expand(grid)
    assert {(s.scenario, s.robots, s.allocator, s.seed) for s in specs} == {
        (f"thesis-exp{n}", 3, allocator, seed)
        for n in range(1, 6)
        for allocator in ("factor-graph", "hungarian")
        for seed in range(10)
    }
