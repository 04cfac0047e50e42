"""Random start poses (``robots.starts: random``): spread, roomy, out of each other's
sight and in one connected space, checked against brute-force references; seeded; and a
request the world cannot meet is one error naming the field."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from acslam.config import load_scenario_config
from acslam.errors import ConfigError
from acslam.scenario import build_scenario, load_scenario
from acslam.worlds.starts import START_CLEARANCE_RADII, line_of_sight
from acslam.worlds.world import World


def _random_starts_file(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "random-starts.yaml"
    path.write_text(f"name: random-starts\nworld: {{generator: dungeon}}\n{body}")
    return path


def _blocked_by_sampling(world: World, a_xy: np.ndarray, b_xy: np.ndarray) -> bool:
    """Brute force: a point every 1/40 cell along the segment, any in an occupied cell."""
    spec = world.spec
    samples = math.ceil(np.hypot(*(b_xy - a_xy)) / (spec.resolution_m / 40)) + 1
    fractions = np.linspace(0.0, 1.0, samples)[:, None]
    cells = spec.world_to_cell(a_xy * (1 - fractions) + b_xy * fractions)
    return bool(world.occupied[cells[:, 0], cells[:, 1]].any())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_starts_are_apart_roomy_connected_and_out_of_sight(
    tmp_path: Path, seed: int
) -> None:
    path = _random_starts_file(
        tmp_path, "robots: {count: 4, starts: random, min_start_separation_m: 4.0}\n"
    )
    scenario = load_scenario(path, seed=seed)
    world, starts = scenario.world, scenario.starts
    radius_m = scenario.config.robots.radius_m
    assert starts.shape == (4, 3)
    assert np.all(np.abs(starts[:, 2]) <= math.pi)
    reachable = world.reachable_free(starts[0, 0], starts[0, 1], radius_m)
    for x, y, _ in starts:
        assert world.clearance_at(x, y, max_m=2.0) >= START_CLEARANCE_RADII * radius_m
        row, col = world.spec.world_to_cell(np.array([[x, y]]))[0]
        assert reachable[row, col]
    for a, b in itertools.combinations(starts[:, :2], 2):
        assert np.hypot(*(a - b)) >= 4.0
        assert _blocked_by_sampling(world, a, b)
        assert not line_of_sight(world, a, b)


def test_line_of_sight_agrees_with_sampling_on_random_segments() -> None:
    scenario = load_scenario("dungeon")
    world = scenario.world
    generator = np.random.default_rng(5)
    free = np.argwhere(~world.occupied)
    agree = []
    for _ in range(300):
        a, b = world.spec.cell_to_world(free[generator.integers(0, len(free), 2)])
        agree.append(line_of_sight(world, a, b) != _blocked_by_sampling(world, a, b))
    # Sampling can miss a corner a segment only clips; the exact traversal cannot.
    assert np.mean(agree) >= 0.98


def test_random_starts_are_seeded_and_free_of_a_start_list(tmp_path: Path) -> None:
    path = _random_starts_file(tmp_path, "robots: {starts: random}\n")
    first = load_scenario(path, robots=5, seed=3).starts
    assert first.shape == (5, 3)
    assert np.array_equal(first, load_scenario(path, robots=5, seed=3).starts)
    assert not np.array_equal(first, load_scenario(path, robots=5, seed=4).starts)
    assert load_scenario(path, seed=3).robot_count == 1


def test_a_team_the_world_cannot_hold_apart_is_one_error_naming_the_field(
    tmp_path: Path,
) -> None:
    path = _random_starts_file(
        tmp_path, "robots: {count: 3, starts: random, min_start_separation_m: 40}\n"
    )
    config, source = load_scenario_config(path)
    with pytest.raises(ConfigError) as error:
        build_scenario(config, source)
    message = str(error.value)
    assert "robots.starts" in message and "min_start_separation_m" in message


def test_an_unknown_starts_word_is_refused_by_the_schema(tmp_path: Path) -> None:
    path = _random_starts_file(tmp_path, "robots: {count: 2, starts: randomly}\n")
    with pytest.raises(ConfigError) as error:
        load_scenario_config(path)
    assert "robots.starts" in str(error.value) and "random" in str(error.value)
