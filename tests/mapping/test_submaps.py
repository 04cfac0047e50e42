"""Submap mapper: equal to exact integration until a correction, exact composition after
any sequence of corrections, analytic rigid placements, and a whole exploration."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from acslam.config import AlgorithmsConfig
from acslam.mapping.occupancy import TeamMap, grid_spec_for_bounds
from acslam.mapping.params import SubmapMappingConfig
from acslam.mapping.submaps import SubmapTeamMap
from acslam.runner import run_exploration
from acslam.scenario import load_scenario

CONFIG = SubmapMappingConfig(max_range_m=3.0, submap_travel_m=0.5, submap_max_scans=6)


def _scans(rng: np.random.Generator, count: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(robot id, ranges, sensor pose) of ``count`` scans by 3 robots driving along x."""
    scans = []
    for i in range(count):
        robot_id = i % 3
        ranges = rng.uniform(0.3, 2.5, 72)
        ranges[rng.random(72) < 0.1] = np.inf
        pose = np.array([-2.0 + 0.08 * (i // 3), -2.0 + 2.0 * robot_id, rng.uniform(-0.2, 0.2)])
        scans.append((robot_id, ranges, pose))
    return scans


ANGLES = np.linspace(-np.pi, np.pi, 72, endpoint=False)
SPEC = grid_spec_for_bounds(-6.0, -6.0, 6.0, 6.0, 0.05)


def _grids(team) -> list[np.ndarray]:
    return [team.global_grid.accumulator_fixed] + [
        team.robot_grid(i).accumulator_fixed for i in range(3)
    ]


def test_without_corrections_the_map_equals_exact_integration() -> None:
    rng = np.random.default_rng(3)
    exact, submaps = TeamMap(CONFIG, spec=SPEC), SubmapTeamMap(CONFIG, spec=SPEC)
    for index, (robot_id, ranges, pose) in enumerate(_scans(rng, 60)):
        for team in (exact, submaps):
            team.add_scan(robot_id, index, ranges, ANGLES, pose, 3.5)
    # 20 scans per robot over 1.5 m: the travel and count limits both open new submaps.
    assert submaps.submap_count >= 9
    for got, want in zip(_grids(submaps), _grids(exact), strict=True):
        assert np.array_equal(got, want)
    assert len(submaps) == 60


def _map_with_corrections(
    scans: list, corrections: list[list[tuple[int, np.ndarray]]]
) -> SubmapTeamMap:
    """Insert the scans; after every 7th, apply that round's ``(index, pose)`` moves."""
    team = SubmapTeamMap(CONFIG, spec=SPEC)
    rounds = iter(corrections)
    for index, (robot_id, ranges, pose) in enumerate(scans):
        team.add_scan(robot_id, index, ranges, ANGLES, pose)
        if index % 7 == 6:
            for moved, new_pose in next(rounds):
                team.move_scan(moved, new_pose)
    return team


def test_any_sequence_of_corrections_equals_composing_from_scratch() -> None:
    rng = np.random.default_rng(7)
    scans = _scans(rng, 63)
    # Corrections arrive while the robots keep mapping (open submaps included); an index
    # may be corrected many times.
    corrections, latest = [], {}
    for end in range(6, 63, 7):
        moves = []
        for moved in rng.choice(end + 1, size=6, replace=False):
            pose = latest.get(int(moved), scans[moved][2]) + rng.normal(0.0, [0.1, 0.1, 0.08])
            latest[int(moved)] = pose
            moves.append((int(moved), pose))
        corrections.append(moves)
    team = _map_with_corrections(scans, corrections)

    # From scratch: each index moved once, at its first correction, straight to its final
    # pose. A submap closes at its anchor's first correction, so both group scans alike.
    seen: set[int] = set()
    once = []
    for moves in corrections:
        once.append([(m, latest[m]) for m, _ in moves if m not in seen])
        seen.update(m for m, _ in moves)
    fresh = _map_with_corrections(scans, once)
    assert sum(len(m) for m in corrections) > sum(len(m) for m in once) > 20
    assert fresh.submap_count == team.submap_count
    for got, want in zip(_grids(team), _grids(fresh), strict=True):
        assert np.array_equal(got, want)
    assert np.array_equal(team.combined([0, 1, 2]).accumulator_fixed, _grids(team)[0])
    # The corrections changed the map; moving every index back undoes them exactly.
    uncorrected = _map_with_corrections(scans, [[(m, scans[m][2]) for m, _ in r] for r in once])
    assert not np.array_equal(_grids(team)[0], _grids(uncorrected)[0])
    for moved in latest:
        team.move_scan(moved, scans[moved][2])
    for got, want in zip(_grids(team), _grids(uncorrected), strict=True):
        assert np.array_equal(got, want)


def _single_submap(pose: np.ndarray) -> tuple[SubmapTeamMap, np.ndarray]:
    rng = np.random.default_rng(11)
    team = SubmapTeamMap(CONFIG, spec=SPEC)
    team.add_scan(0, 0, rng.uniform(0.3, 2.0, 72), ANGLES, pose)
    return team, np.array(team.global_grid.accumulator_fixed)


def test_a_translation_by_whole_cells_shifts_the_submap_cell_for_cell() -> None:
    pose = np.array([0.025, 0.025, 0.3])
    team, before = _single_submap(pose)
    team.move_scan(0, pose + np.array([3 * 0.05, -2 * 0.05, 0.0]))
    want = np.zeros_like(before)
    want[:-2, 3:] = before[2:, :-3]
    assert np.array_equal(team.global_grid.accumulator_fixed, want)


def test_a_quarter_turn_about_a_cell_centre_rotates_the_array() -> None:
    # The grid's cell centres sit at odd multiples of 0.025 m; (0.025, 0.025) is the centre
    # of cell (120, 120) of the 240 x 240 grid, so a quarter turn maps centres to centres.
    pose = np.array([0.025, 0.025, 0.0])
    team, before = _single_submap(pose)
    team.move_scan(0, pose + np.array([0.0, 0.0, math.pi / 2]))
    window = before[20:221, 20:221]  # centred on cell (120, 120), the scan's whole reach
    assert window.sum() == before.sum()
    want = np.zeros_like(before)
    # np.rot90 turns counter-clockwise as displayed (rows down); rows grow along y here.
    want[20:221, 20:221] = np.rot90(window, k=-1)
    assert np.array_equal(team.global_grid.accumulator_fixed, want)


def test_the_submaps_mapper_is_chosen_by_name() -> None:
    algorithms = AlgorithmsConfig().with_stage("mapper", "submaps")
    assert isinstance(algorithms.mapper, SubmapMappingConfig)
    assert algorithms.mapper.submap_travel_m == 2.0


def test_a_team_explores_with_the_submaps_mapper(tiny_scenario: Path, tmp_path: Path) -> None:
    data = yaml.safe_load(tiny_scenario.read_text())
    data["algorithms"] = {"mapper": {"name": "submaps", "submap_travel_m": 0.5}}
    path = tiny_scenario.parent / "submaps.yaml"
    path.write_text(yaml.safe_dump(data))
    metrics = run_exploration(load_scenario(path), tmp_path, max_time_s=120.0)
    # The thesis-grid bounds every mapper must keep.
    assert metrics["completed"], metrics["reason"]
    assert metrics["coverage"]["explored_fraction_of_reachable"] >= 0.99
    assert metrics["safety"]["obstacle_collisions"] == 0
    assert metrics["safety"]["robot_collisions"] == 0
    assert metrics["mapping"]["accuracy"] >= 0.95
    assert max(r["rmse_m"] for r in metrics["localization"].values()) <= 0.10
