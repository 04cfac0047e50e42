"""A team with unknown relative starts: a frame per robot, merged online at the true pose
and not at a decoy's, with the merged frame what known starts would have made."""

from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from acslam.cli import cli
from acslam.experiments.grid import builtin_grid, expand
from acslam.geometry import between
from acslam.grid import GridSpec
from acslam.messages import LidarScan
from acslam.pipeline.frames import (
    CATCH_UP_IN_CYCLE,
    MERGE_LANE,
    MERGED_START_SIGMAS,
    FramedServer,
    frame_grid_spec,
    sighting,
)
from acslam.pipeline.server import Server, small_objects_m
from acslam.planning.field import DistanceField, ObstacleField
from acslam.runner import run_exploration
from acslam.scenario import UNKNOWN_STARTS_SUFFIX, load_scenario
from acslam.sources.simulated import SimulatedSource


def test_a_frame_grid_holds_the_building_wherever_and_however_its_robot_started() -> None:
    extent = GridSpec(2.0, -1.0, 0.05, 120, 200)  # 10 m x 6 m
    spec = frame_grid_spec(extent)
    left, right, bottom, top = spec.extent_m
    assert left == bottom == -right == -top  # a square about the origin ...
    assert (-left / spec.resolution_m).is_integer()  # ... which is a cell corner
    corners = [(x, y) for x in extent.extent_m[:2] for y in extent.extent_m[2:]]
    rng = np.random.default_rng(0)
    for _ in range(200):
        start = np.array([rng.uniform(2.0, 12.0), rng.uniform(-1.0, 5.0), rng.uniform(-4, 4)])
        for corner in corners:
            x, y, _ = between(start, np.array([*corner, 0.0]))
            assert left <= x <= right and bottom <= y <= top


def test_an_obstacle_point_over_a_field_is_the_nearer_obstacle() -> None:
    base = DistanceField(np.full((40, 40), 0.7), GridSpec(0.0, 0.0, 0.05, 40, 40))
    field = ObstacleField(base, np.array([[1.5, 1.0]]))
    value, gradient = field.value_and_gradient(np.array([[1.0, 1.0], [0.5, 1.0]]))
    np.testing.assert_allclose(value, [0.5, 0.7])  # the point is nearer, then the field
    np.testing.assert_allclose(gradient[0], [-1.0, 0.0])  # away from the point
    np.testing.assert_allclose(field.value(np.array([1.0, 1.0])), 0.5)


def _two_rooms(tiny_scenario: Path, relative_starts: str) -> Path:
    """The tiny world's two rooms, alike but for the east room's shelf; one robot in each,
    facing each other's room."""
    data = yaml.safe_load(tiny_scenario.read_text())
    data["robots"].update(
        count=2,
        starts=[[1.0, 1.5, 0.0], [8.5, 4.5, math.pi]],
        relative_starts=relative_starts,
    )
    path = tiny_scenario.parent / f"two-rooms-{relative_starts}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def two_rooms_run(
    tiny_scenario: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[dict, Path]:
    scenario = load_scenario(_two_rooms(tiny_scenario, "unknown"))
    folder = tmp_path_factory.mktemp("two-rooms") / "run"
    return run_exploration(scenario, folder, 60.0), folder


def test_robots_in_two_like_rooms_merge_at_the_true_pose_not_the_turned_one(
    two_rooms_run: tuple[dict, Path],
) -> None:
    """Turned half a circle, the shelf-less west room fits the east room, but puts the
    shelf in the west room's free space (the mapping tests show that fit scoring above
    the truth); the merge waits for the robots to see through the door."""
    metrics, _ = two_rooms_run
    (merge,) = metrics["unknown_starts"]["merges"]
    assert not merge["false"]
    assert merge["error_m"] <= 0.1 and merge["error_rad"] <= 0.02
    assert merge["false_locally"] is False and merge["local_error_m"] <= 0.1
    assert metrics["unknown_starts"]["all_merged"] and metrics["completed"]
    assert merge["time_s"] < metrics["timing"]["total_s"]
    # The robots see each other through the door, so they met before the merge.
    assert merge["met_s"] is not None and merge["met_s"] <= merge["time_s"]
    assert metrics["safety"]["robot_collisions"] == metrics["safety"]["obstacle_collisions"] == 0
    assert metrics["coverage"]["explored_fraction_of_reachable"] >= 0.99
    assert metrics["mapping"]["accuracy"] >= 0.95
    assert max(r["rmse_m"] for r in metrics["localization"].values()) <= 0.1


def test_each_merge_has_its_figure_and_the_frames_are_placed_for_scoring(
    two_rooms_run: tuple[dict, Path],
) -> None:
    metrics, folder = two_rooms_run
    assert (folder / "merges" / "merge_1.png").is_file()
    report = (folder / "report.html").read_text()
    assert "Merges of frames" in report and "Merge 1, at" in report
    assert "robots first met [s]" in report
    robots = metrics["unknown_starts"]["robots"]
    assert robots["robot_0"]["start_error_m"] <= 0.01  # robot 0's frame is the team's
    assert robots["robot_1"]["merged_s"] == metrics["unknown_starts"]["merges"][0]["time_s"]


@pytest.mark.parametrize(("mapper", "parts"), [("log-odds", 1), ("log-odds", 2), ("submaps", 1)])
def test_a_merged_frame_is_what_known_starts_would_have_made(
    tiny_scenario: Path, mapper: str, parts: int
) -> None:
    """A server built late and caught up on every message its robots sent localizes and
    maps exactly as one that stepped through them from the start: also when the catch-up
    comes in two parts (a served merge's, see below; here the second from two thirds on,
    where corrections re-place scans the first part mapped), the log-odds mapper having
    mapped each scan once per part at its last re-placed pose, and with submaps, which
    follow every correction."""
    path = _two_rooms(tiny_scenario, "known")
    data = yaml.safe_load(path.read_text())
    # Keyframes reported moved at 2 mm: the replay's corrections re-place scans.
    data["algorithms"] = {
        "mapper": {"name": mapper},
        "localizer": {"name": "isam2", "correction_threshold_m": 0.002},
    }
    path.write_text(yaml.safe_dump(data))
    scenario = load_scenario(path)
    config = scenario.config
    sim = scenario.simulator()
    stepped = Server(config, scenario.starts, scenario.world.spec)
    substeps = round(config.algorithms.planning.control_period_s / config.sim.dt_s)
    source = SimulatedSource(sim, substeps)
    history = []
    while source.time_s < 8.0:
        messages = source.receive()
        source.deliver(stepped.step(messages, source.time_s))
        history.append((source.time_s, messages))
        source.advance()
    caught_up = Server(config, scenario.starts, scenario.world.spec)
    for part in np.split(np.arange(len(history)), [2 * len(history) // 3] if parts == 2 else []):
        for k in part:
            caught_up.catch_up(history[k][1], history[k][0])
        caught_up.caught_up()
    for robot in range(2):
        stamps, poses = stepped.snapshot(0.0).localization.trajectory(robot)
        again_stamps, again_poses = caught_up.snapshot(0.0).localization.trajectory(robot)
        np.testing.assert_array_equal(stamps, again_stamps)
        np.testing.assert_array_equal(poses, again_poses)
    np.testing.assert_array_equal(
        stepped.snapshot(0.0).map.occupancy_values(), caught_up.snapshot(0.0).map.occupancy_values()
    )


def test_the_same_seed_merges_the_same_way(tmp_path: Path) -> None:
    scenario = load_scenario("thesis-exp1", robots=2).with_unknown_starts()
    first = run_exploration(scenario, tmp_path / "a", 8.0)["unknown_starts"]
    second = run_exploration(scenario, tmp_path / "b", 8.0)["unknown_starts"]
    assert first["merges"] and first["merges"] == second["merges"]


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--record", "run.mcap"], "not with unknown starts"),
        (["--viz", "rerun"], "not with unknown starts"),
    ],
)
def test_what_shows_one_team_frame_refuses_unknown_starts(extra: list[str], says: str) -> None:
    result = CliRunner().invoke(
        cli, ["run", "--scenario", "thesis-exp1", "--unknown-starts", *extra]
    )
    assert result.exit_code != 0 and says in result.output


def test_a_sweep_without_known_starts_keeps_its_runs_apart() -> None:
    grid = builtin_grid("thesis")
    known = expand(grid, seeds=1)
    unknown = expand(grid, seeds=1, unknown_starts=True)
    assert [s.run_id + UNKNOWN_STARTS_SUFFIX for s in known] == [s.run_id for s in unknown]
    assert all(
        s.key() == {**k.key(), "unknown_starts": True} for s, k in zip(unknown, known, strict=True)
    )
    scenario = load_scenario("thesis-exp1").with_unknown_starts()
    assert scenario.config.name == "thesis-exp1" + UNKNOWN_STARTS_SUFFIX
    assert scenario.with_unknown_starts().config.name == scenario.config.name


def _scan(ranges_m: np.ndarray) -> LidarScan:
    return LidarScan(0, 0.0, np.radians(np.arange(-180.0, 180.0)), ranges_m, range_max_m=8.0)


def test_a_sighting_tells_a_robot_from_a_wall_and_from_empty_space() -> None:
    """A robot of radius 0.105 m 2 m ahead spans 3 beams at 1 degree: beams that end on
    it with longer ones beside it show it; beams that all run on past refute it; a wall
    there, or something nearer in the way, tells nothing."""
    viewer, target = np.zeros(3), np.array([2.0, 0.0])
    angles = np.arange(-180.0, 180.0)
    open_room = np.full(360, 5.0)
    with_robot = np.where(np.abs(angles) <= 3, 1.92, open_room)
    assert sighting(viewer, _scan(with_robot), target, 0.105) is True
    assert sighting(viewer, _scan(open_room), target, 0.105) is False
    assert sighting(viewer, _scan(np.full(360, 2.0)), target, 0.105) is None  # a wall
    hidden = np.where(np.abs(angles) <= 10, 1.0, open_room)
    assert sighting(viewer, _scan(hidden), target, 0.105) is None
    assert sighting(viewer, _scan(open_room), np.array([7.95, 0.0]), 0.105) is None  # too far


@pytest.mark.parametrize("distance_m", [1.0, 2.0, 3.5, 5.5])
def test_a_robot_in_free_space_is_seen_near_its_centre_and_a_wall_is_not_a_robot(
    distance_m: float,
) -> None:
    """Beams at 1 degree that hit a robot of radius r end on its near half, whose mean lies
    r * pi / 4 before its centre (beams are about evenly spread across it): the centre
    guessed one radius behind that mean is within r * (1 - pi / 4) plus the beams'
    spacing of the truth. At 5.5 m only two beams hit it. Unexplained returns as wide as a
    wall, or a single one, are no robot."""
    radius_m, bearing = 0.105, 0.4
    centre = distance_m * np.array([math.cos(bearing), math.sin(bearing)])
    viewer = np.array([0.0, 0.0, 0.3])
    angles = np.radians(np.arange(-180.0, 180.0)) + viewer[2]
    directions = np.column_stack([np.cos(angles), np.sin(angles)])
    # Where each beam meets the circle (the nearer root), else 5 m on to a wall.
    along = directions @ centre
    square = along**2 - (distance_m**2 - radius_m**2)
    hits = (square >= 0) & (along > 0)
    ranges = np.where(hits, along - np.sqrt(np.where(hits, square, 0.0)), 5.0)
    ends = ranges[:, None] * directions
    (found,) = small_objects_m(viewer, ends, hits, radius_m)
    spacing_m = distance_m * math.radians(1.0)
    assert np.linalg.norm(found - centre) <= radius_m * (1 - math.pi / 4) + spacing_m
    wall = np.abs(np.degrees(angles - viewer[2])) < 20  # 40 beams at 5 m: 3.5 m wide
    assert small_objects_m(viewer, ends, wall, radius_m).shape == (0, 2)
    one = np.flatnonzero(hits)[:1]
    assert small_objects_m(viewer, ends, np.isin(np.arange(360), one), radius_m).shape == (0, 2)


class _LateFuture(Future):
    """A job's result, said to be ready only at the ``polls``-th look."""

    def __init__(self, value: object, polls: int) -> None:
        super().__init__()
        self._value, self._polls = value, polls
        if polls <= 0:
            self.set_result(value)

    def done(self) -> bool:
        self._polls -= 1
        if self._polls <= 0 and not super().done():
            self.set_result(self._value)
        return super().done()


class _LateMergeLane:
    """Jobs as in process, but the merge lane's jobs that found a merge are ready only
    ``delays`` control cycles after they were scheduled: a look and a catch-up that ran
    beside the control loop (as in a served run)."""

    def __init__(self, delays: list[int]) -> None:
        self._delays = delays

    def submit(self, lane: str, job: Callable[[], object]) -> Future:
        result = job()
        if lane != MERGE_LANE or result is None or not self._delays:
            return _LateFuture(result, 0)
        return _LateFuture(result, self._delays.pop(0))

    def close(self) -> None:
        return None


def test_a_merge_found_beside_the_control_loop_is_taken_in_caught_up_exactly() -> None:
    """The look that confirms the merge is ready 25 cycles after its evidence, and the
    catch-up of those 25 cycles 5 cycles later (still more than CATCH_UP_IN_CYCLE behind,
    so it went to the merge lane): the frame then taken in holds exactly what one server
    with the merged starts, fed every message at once, holds."""
    scenario = load_scenario("thesis-exp1", robots=2).with_unknown_starts()
    config = scenario.config
    jobs = _LateMergeLane([25, 5])
    server = FramedServer(config, 2, scenario.world.spec, lambda: jobs)
    substeps = round(config.algorithms.planning.control_period_s / config.sim.dt_s)
    source = SimulatedSource(scenario.simulator(), substeps)
    history = []
    snapshot = server.step([], 0.0)
    while not snapshot.merges and source.time_s < 20.0:
        messages = source.receive()
        history.append((source.time_s, messages))
        snapshot = server.step(messages, source.time_s)
        source.deliver(snapshot)
        source.advance()
    (merge,) = snapshot.merges
    # The look is asked in the cycle that scheduled it, then 24 more; the catch-up 5.
    assert merge.time_s - merge.poses_time_s == pytest.approx(2.9)
    assert CATCH_UP_IN_CYCLE < 25
    (frame,) = snapshot.frames
    reference = Server(
        config, frame.starts, frame_grid_spec(scenario.world.spec),
        start_sigmas={1: MERGED_START_SIGMAS}, scan_obstacles=True,
    )  # fmt: skip
    for time_s, messages in history:
        reference.catch_up(sorted(messages, key=lambda m: m.robot_id), time_s)
    reference.caught_up()
    for robot in range(2):
        stamps, poses = frame.snapshot.localization.trajectory(robot)
        again_stamps, again_poses = reference.snapshot(0.0).localization.trajectory(robot)
        np.testing.assert_array_equal(stamps, again_stamps)
        np.testing.assert_array_equal(poses, again_poses)
