"""Merging maps of unknown relative pose: a found merge, a refused decoy, the composition."""

from __future__ import annotations

import json
import math
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy import ndimage

from acslam.cli import cli
from acslam.geometry import compose, transform_points, wrap_angle
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from acslam.mapping.merge import MergeParams, Pin, find_merge, merge_maps, place_grid
from acslam.worlds.mapio import load_map, save_map

RESOLUTION_M = 0.05
Rect = tuple[float, float, float, float]


def building(size_m: tuple[float, float], free: list[Rect]) -> tuple[np.ndarray, GridSpec]:
    """Solid everywhere but the free rectangles (x0, y0, x1, y1), as a truth map."""
    spec = GridSpec(
        0.0, 0.0, RESOLUTION_M, round(size_m[1] / RESOLUTION_M), round(size_m[0] / RESOLUTION_M)
    )
    centres = spec.cell_to_world(np.argwhere(np.ones(spec.shape, dtype=bool)))
    inside = np.zeros(len(centres), dtype=bool)
    for x0, y0, x1, y1 in free:
        inside |= (
            (centres[:, 0] > x0)
            & (centres[:, 0] < x1)
            & (centres[:, 1] > y0)
            & (centres[:, 1] < y1)
        )
    values = np.where(inside, FREE, OCCUPIED).astype(np.int8).reshape(spec.shape)
    return values, spec


def seen_map(
    truth: tuple[np.ndarray, GridSpec],
    frame: np.ndarray,
    seen: Callable[[np.ndarray], np.ndarray],
    size_m: float,
) -> tuple[np.ndarray, GridSpec]:
    """What a robot whose map frame sits at ``frame`` (in the truth's frame) knows, as a
    LiDAR map holds it: the free cells where ``seen`` (of truth-frame points) holds and
    the wall faces beside them, unknown elsewhere (a wall's inside is never seen),
    rasterised on its own grid of ``size_m`` around its origin."""
    values, spec = truth
    faces = (values == OCCUPIED) & ndimage.binary_dilation(values == FREE, np.ones((3, 3)))
    visible = np.where(faces, OCCUPIED, np.where(values == FREE, FREE, UNKNOWN))
    cells = round(size_m / RESOLUTION_M)
    own = GridSpec(-size_m / 2, -size_m / 2, RESOLUTION_M, cells, cells)
    centres = own.cell_to_world(np.argwhere(np.ones(own.shape, dtype=bool)))
    world = transform_points(frame, centres)
    truth_cells = spec.world_to_cell(world)
    inside = spec.contains(truth_cells) & seen(world)
    out = np.full(len(centres), UNKNOWN, dtype=np.int8)
    out[inside] = visible[truth_cells[inside, 0], truth_cells[inside, 1]]
    return out.reshape(own.shape).astype(np.int8), own


def two_rooms() -> tuple[np.ndarray, GridSpec]:
    """Two rooms of different shapes, a door between them, a pillar and a partition."""
    values, spec = building(
        (16.0, 10.0),
        [(1.0, 1.0, 7.0, 7.0), (6.9, 3.0, 8.3, 4.0), (8.2, 1.0, 14.5, 8.5)],
    )
    centres = spec.cell_to_world(np.argwhere(np.ones(spec.shape, dtype=bool)))
    pillar = (np.abs(centres[:, 0] - 3.0) < 0.25) & (np.abs(centres[:, 1] - 5.0) < 0.25)
    partition = (
        (np.abs(centres[:, 1] - 6.0) < 0.08) & (centres[:, 0] > 10.0) & (centres[:, 0] < 13.0)
    )
    values.reshape(-1)[pillar | partition] = OCCUPIED
    return values, spec


def _pose_error(found: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    return float(np.linalg.norm(found[:2] - truth[:2])), abs(wrap_angle(found[2] - truth[2]))


def test_two_maps_of_a_two_room_building_merge_at_their_true_relative_pose() -> None:
    truth = two_rooms()
    frame_a = np.array([4.0, 4.0, 0.0])
    frame_b = np.array([11.0, 5.0, 2.3])  # robot B started in the east room, turned
    map_a = seen_map(truth, frame_a, lambda p: p[:, 0] < 9.5, 16.0)  # west room and door
    map_b = seen_map(truth, frame_b, lambda p: p[:, 0] > 5.5, 16.0)  # east room and door
    decision = find_merge(*map_a, *map_b)
    assert decision.accepted, decision.reason
    relative = compose(np.array([-frame_a[0], -frame_a[1], 0.0]), frame_b)  # B in A's frame
    distance_m, angle_rad = _pose_error(decision.pose, relative)
    assert distance_m <= 2 * RESOLUTION_M
    assert angle_rad <= 2 * decision.angle_step_rad
    merged, spec = merge_maps(*map_a, *map_b, decision.pose)
    # Every known cell of the merged map against the truth, and the whole building known.
    both = seen_map(truth, frame_a, lambda p: np.ones(len(p), dtype=bool), 16.0)
    centres = spec.cell_to_world(np.argwhere(merged != UNKNOWN))
    truth_cells = truth[1].world_to_cell(transform_points(frame_a, centres))
    agree = merged[merged != UNKNOWN] == truth[0][truth_cells[:, 0], truth_cells[:, 1]]
    assert agree.mean() >= 0.98
    assert np.count_nonzero(merged == FREE) >= 0.97 * np.count_nonzero(both[0] == FREE)


def test_maps_that_do_not_overlap_are_not_merged() -> None:
    truth = two_rooms()
    map_a = seen_map(truth, np.array([4.0, 4.0, 0.0]), lambda p: p[:, 0] < 6.5, 16.0)
    map_b = seen_map(truth, np.array([11.0, 5.0, 2.3]), lambda p: p[:, 0] > 9.0, 16.0)
    decision = find_merge(*map_a, *map_b)
    assert not decision.accepted


def test_a_map_without_walls_is_refused_with_its_reason() -> None:
    """Nothing to match, with or without a pin: one clear reason, no search."""
    spec = GridSpec(0.0, 0.0, RESOLUTION_M, 40, 40)
    empty_room = np.full(spec.shape, FREE, dtype=np.int8)
    decision = find_merge(empty_room, spec, empty_room, spec)
    assert not decision.accepted and decision.reason == "map B has no occupied cells to match"
    building_values, building_spec = two_rooms()
    pin = Pin(np.zeros(2), np.array([40.0, 40.0]), 0.5, 10.0)  # far from B's walls
    decision = find_merge(
        building_values, building_spec, building_values, building_spec, pin=pin
    )  # fmt: skip
    assert not decision.accepted and "within 10 m of the pinned point" in decision.reason


def symmetric_hall(pillar: bool) -> tuple[np.ndarray, GridSpec]:
    """A corridor with the same room at each end, turned by 180 degrees about the centre
    (10, 5); ``pillar`` puts a 0.3 m pillar in the east room only, which breaks the
    symmetry."""
    values, spec = building(
        (20.0, 10.0),
        [
            (1.0, 2.0, 5.0, 8.0),
            (4.9, 4.4, 15.1, 5.6),
            (15.0, 2.0, 19.0, 8.0),
            (2.0, 8.0, 3.0, 9.0),
            (17.0, 1.0, 18.0, 2.0),
        ],
    )
    if pillar:
        centres = spec.cell_to_world(np.argwhere(np.ones(spec.shape, dtype=bool)))
        near = (np.abs(centres[:, 0] - 17.0) < 0.15) & (np.abs(centres[:, 1] - 6.5) < 0.15)
        values.reshape(-1)[near] = OCCUPIED
    return values, spec


def test_a_symmetric_view_is_not_merged_until_the_symmetry_is_broken() -> None:
    """A knows the whole hall. B has seen only the east room, which from inside looks the
    same as the west one turned: no merge. Once the east room has its pillar, in A's map
    and in B's view, the twin pose puts B's pillar in A's free space, and B merges at the
    true pose."""
    frame_a = np.array([10.0, 5.0, 0.0])
    frame_b = np.array([17.0, 5.0, 0.8])
    relative = compose(np.array([-10.0, -5.0, 0.0]), frame_b)
    east_room = lambda p: p[:, 0] > 14.5  # noqa: E731
    everything = lambda p: np.ones(len(p), dtype=bool)  # noqa: E731

    plain = symmetric_hall(pillar=False)
    decision = find_merge(
        *seen_map(plain, frame_a, everything, 22.0), *seen_map(plain, frame_b, east_room, 12.0)
    )
    assert not decision.accepted
    assert decision.reason.startswith("ambiguous")
    assert decision.second_score >= 0.9 * decision.score

    broken = symmetric_hall(pillar=True)
    decision = find_merge(
        *seen_map(broken, frame_a, everything, 22.0), *seen_map(broken, frame_b, east_room, 12.0)
    )
    assert decision.accepted, decision.reason
    # The twin still scores nearly as well: the pillar is a few points of B's walls. It
    # is the free space at the pillar's twin place that rules it out.
    assert decision.second_score >= 0.9 * decision.score
    distance_m, angle_rad = _pose_error(decision.pose, relative)
    assert distance_m <= 2 * RESOLUTION_M and angle_rad <= 2 * decision.angle_step_rad


def test_a_robot_seen_where_it_stands_pins_the_search_and_breaks_the_symmetry() -> None:
    """The plain symmetric hall, which the whole-map search must refuse: A saw B's robot
    (at B's origin) 0.2 m from where it stood. Only poses that put it within the pin's
    0.5 m are searched, so the twin pose, which puts it 14 m away in the west room, is not
    a rival: B merges at the true pose. A robot seen where B's is not (in the corridor)
    gives no merge."""
    frame_a = np.array([10.0, 5.0, 0.0])
    frame_b = np.array([17.0, 5.0, 0.8])
    relative = compose(np.array([-10.0, -5.0, 0.0]), frame_b)
    plain = symmetric_hall(pillar=False)
    map_a = seen_map(plain, frame_a, lambda p: np.ones(len(p), dtype=bool), 22.0)
    map_b = seen_map(plain, frame_b, lambda p: p[:, 0] > 14.5, 12.0)
    seen_at = relative[:2] + np.array([0.12, -0.16])
    decision = find_merge(*map_a, *map_b, pin=Pin(seen_at, np.zeros(2), 0.5, 10.0))
    assert decision.accepted, decision.reason
    distance_m, angle_rad = _pose_error(decision.pose, relative)
    assert distance_m <= 2 * RESOLUTION_M and angle_rad <= 2 * decision.angle_step_rad
    in_corridor = Pin(np.array([-2.0, 0.0]), np.zeros(2), 0.5, 10.0)
    assert not find_merge(*map_a, *map_b, pin=in_corridor).accepted


def test_the_best_scoring_pose_is_passed_over_when_it_puts_walls_in_free_space() -> None:
    """Two like rooms; B knows the east one, with its pillar. A saw all of the west room
    but only the south half of the east one: B fits the west room best by score, but
    there its pillar stands in A's free space, so the east room, where nothing
    contradicts B, is the merge."""
    truth = building((22.0, 10.0), [(1.0, 1.0, 9.0, 8.0), (12.0, 1.0, 20.0, 8.0)])
    values, spec = truth
    centres = spec.cell_to_world(np.argwhere(np.ones(spec.shape, dtype=bool)))
    x, y = centres[:, 0], centres[:, 1]
    # The same wall stub in each room breaks each room's own symmetry ...
    stubs = (np.abs(y - 2.0) < 0.08) & (((x > 1.0) & (x < 3.0)) | ((x > 12.0) & (x < 14.0)))
    # ... and a pillar only in the east room tells the rooms apart.
    pillar = (np.abs(x - 16.0) < 0.6) & (np.abs(y - 6.0) < 0.6)
    values.reshape(-1)[stubs | pillar] = OCCUPIED
    frame_a = np.array([11.0, 5.0, 0.0])
    frame_b = np.array([16.0, 4.0, 1.2])
    map_a = seen_map(truth, frame_a, lambda p: (p[:, 0] < 10.0) | (p[:, 1] < 4.5), 24.0)
    map_b = seen_map(truth, frame_b, lambda p: p[:, 0] > 11.0, 12.0)
    decision = find_merge(*map_a, *map_b)
    assert decision.accepted, decision.reason
    assert decision.second_score > decision.score  # the west room scored better
    relative = compose(np.array([-11.0, -5.0, 0.0]), frame_b)
    distance_m, angle_rad = _pose_error(decision.pose, relative)
    assert distance_m <= 2 * RESOLUTION_M and angle_rad <= 2 * decision.angle_step_rad


def test_the_same_maps_give_the_same_decision() -> None:
    truth = two_rooms()
    map_a = seen_map(truth, np.array([4.0, 4.0, 0.0]), lambda p: p[:, 0] < 9.5, 16.0)
    map_b = seen_map(truth, np.array([11.0, 5.0, 2.3]), lambda p: p[:, 0] > 5.5, 16.0)
    first, second = find_merge(*map_a, *map_b), find_merge(*map_a, *map_b)
    assert first.accepted == second.accepted and first.score == second.score
    np.testing.assert_array_equal(first.pose, second.pose)


@pytest.mark.parametrize("theta", [0.0, math.pi / 2, 2.0])
def test_merging_a_map_with_itself_moved_restores_its_cells(theta: float) -> None:
    """B is A's own cells in a frame turned by a right angle or not: every known cell of
    A comes back where it was, and nothing else is known."""
    truth = two_rooms()
    frame = np.array([8.0, 5.0, 0.0])
    map_a = seen_map(truth, frame, lambda p: np.ones(len(p), dtype=bool), 18.0)
    pose = np.array([0.0, 0.0, theta])
    map_b = seen_map(map_a, pose, lambda p: np.ones(len(p), dtype=bool), 18.0)
    merged, spec = merge_maps(*map_a, *map_b, pose)
    values_a, spec_a = map_a
    shift = spec_a.world_to_cell(spec.cell_to_world(np.zeros((1, 2), dtype=int)))[0]
    inside = merged[-shift[0] : -shift[0] + spec_a.rows, -shift[1] : -shift[1] + spec_a.cols]
    known = values_a != UNKNOWN
    agree = inside[known] == values_a[known]
    if theta in (0.0, math.pi / 2):
        assert agree.all()  # a right angle maps cells onto cells
    else:
        assert agree.mean() >= 0.97  # resampled: only cells on edges may flip to occupied


@pytest.mark.parametrize("seed", range(3))
def test_a_grid_placed_in_another_reads_each_target_cell_centre_from_the_cell_under_it(
    seed: int,
) -> None:
    """Brute force per target cell: its centre taken into the grid's frame, the cell
    under it read (UNKNOWN off the grid). The grid is mostly unknown, as a frame's square
    grid is, and part of it lies beyond the target."""
    rng = np.random.default_rng(seed)
    spec = GridSpec(-4.0, -3.0, 0.1, 70, 90)
    values = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    r0, c0 = rng.integers(0, 40, 2)
    values[r0 : r0 + 25, c0 : c0 + 35] = rng.choice([FREE, OCCUPIED, UNKNOWN], (25, 35))
    target = GridSpec(-2.0, -1.0, 0.05, 80, 110)
    pose = np.array([*rng.uniform(-1.0, 1.0, 2), rng.uniform(-math.pi, math.pi)])
    placed = place_grid(values, spec, pose, target)
    rows, cols = np.indices(target.shape)
    centres = target.cell_to_world(np.column_stack([rows.ravel(), cols.ravel()]))
    in_grid = transform_points(np.array(_inverse(pose)), centres)
    cells = np.floor((in_grid - [spec.origin_x_m, spec.origin_y_m]) / spec.resolution_m)
    cells = cells.astype(int)[:, ::-1]
    inside = spec.contains(cells)
    expected = np.full(len(centres), UNKNOWN, dtype=np.int8)
    expected[inside] = values[cells[inside, 0], cells[inside, 1]]
    assert (expected != UNKNOWN).sum() > 100
    np.testing.assert_array_equal(placed.ravel(), expected)


def _inverse(pose: np.ndarray) -> np.ndarray:
    """The inverse of a planar pose."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.array([-c * pose[0] - s * pose[1], s * pose[0] - c * pose[1], -pose[2]])


def _saved(tmp_path: Path, name: str, mapped: tuple[np.ndarray, GridSpec]) -> Path:
    return save_map(tmp_path / name, *mapped)[0]


def test_merge_command_writes_the_decision_the_merged_map_and_the_figure(tmp_path: Path) -> None:
    truth = two_rooms()
    frame_b = np.array([11.0, 5.0, 2.3])
    a = _saved(
        tmp_path, "a", seen_map(truth, np.array([4.0, 4.0, 0.0]), lambda p: p[:, 0] < 9.5, 16.0)
    )
    b = _saved(tmp_path, "b", seen_map(truth, frame_b, lambda p: p[:, 0] > 5.5, 16.0))
    result = CliRunner().invoke(cli, ["merge", str(a), str(b), "--out", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    assert result.output.startswith("B lies in A at x ")
    # The rivals: none near the best, or each ruled out by A's free space.
    assert "no other pose scores within 90 %" in result.output or (
        "ruled out by A's free space" in result.output
    )
    decision = json.loads((tmp_path / "out" / "merge.json").read_text())
    assert decision["accepted"] and decision["reason"] == ""
    distance_m, angle_rad = _pose_error(
        np.array(decision["pose_b_in_a"]), np.array([7.0, 1.0, 2.3])
    )
    assert distance_m <= 2 * RESOLUTION_M and angle_rad <= 2 * decision["angle_step_rad"]
    merged, _ = load_map(tmp_path / "out" / "map.yaml")
    assert np.count_nonzero(merged == FREE) > np.count_nonzero(load_map(a)[0] == FREE)
    assert (tmp_path / "out" / "merge.png").stat().st_size > 0


def test_merge_command_refuses_a_decoy_with_its_reason_and_keeps_the_decision(
    tmp_path: Path,
) -> None:
    hall = symmetric_hall(pillar=False)
    everything = lambda p: np.ones(len(p), dtype=bool)  # noqa: E731
    a = _saved(tmp_path, "a", seen_map(hall, np.array([10.0, 5.0, 0.0]), everything, 22.0))
    b = _saved(
        tmp_path, "b", seen_map(hall, np.array([17.0, 5.0, 0.8]), lambda p: p[:, 0] > 14.5, 12.0)
    )
    result = CliRunner().invoke(cli, ["merge", str(a), str(b), "--out", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert result.output.startswith("no merge: ambiguous")
    assert not json.loads((tmp_path / "out" / "merge.json").read_text())["accepted"]
    assert not (tmp_path / "out" / "map.yaml").exists()


def test_maps_of_different_resolutions_are_one_error_naming_the_field(tmp_path: Path) -> None:
    a = save_map(
        tmp_path / "a", np.zeros((10, 10), dtype=np.int8), GridSpec(0.0, 0.0, 0.05, 10, 10)
    )[0]
    b = save_map(
        tmp_path / "b", np.zeros((10, 10), dtype=np.int8), GridSpec(0.0, 0.0, 0.1, 10, 10)
    )[0]
    result = subprocess.run(
        ["acslam", "merge", str(a), str(b), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.startswith(f"acslam: error: {b}: resolution: 0.1 m differs from")
    assert "Traceback" not in result.stderr


def test_a_wall_in_free_space_rules_a_pose_out_however_few_points_it_has() -> None:
    """Two like rooms apart, a 2 m shelf only in the east one. A saw the west room, B
    the east room: nothing overlaps, but B's room fits A's at one shift, with only the
    shelf (under a tenth of B's points) in A's free space. Counting points alone takes
    that pose, 11 m off; the shelf as a wall rules it out."""
    truth = building((22.0, 10.0), [(1.0, 1.0, 10.0, 9.0), (12.0, 1.0, 21.0, 9.0)])
    values, spec = truth
    centres = spec.cell_to_world(np.argwhere(np.ones(spec.shape, dtype=bool)))
    x, y = centres[:, 0], centres[:, 1]
    stubs = (np.abs(y - 2.0) < 0.08) & (((x > 1.0) & (x < 3.0)) | ((x > 12.0) & (x < 14.0)))
    shelf = (np.abs(y - 6.0) < 0.08) & (x > 15.0) & (x < 17.0)
    values.reshape(-1)[stubs | shelf] = OCCUPIED
    map_a = seen_map(truth, np.array([5.0, 5.0, 0.0]), lambda p: p[:, 0] < 10.5, 24.0)
    map_b = seen_map(truth, np.array([16.0, 4.0, 1.2]), lambda p: p[:, 0] > 11.5, 24.0)
    counted = find_merge(*map_a, *map_b, MergeParams(max_contradicting_wall_m=math.inf))
    assert counted.accepted and counted.contradiction < 0.1
    assert _pose_error(counted.pose, compose(np.array([-5.0, -5.0, 0.0]), [16.0, 4.0, 1.2]))[0] > 10
    decision = find_merge(*map_a, *map_b)
    assert not decision.accepted
