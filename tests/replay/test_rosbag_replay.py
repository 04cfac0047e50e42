"""`acslam slam rosbag`: a recorded run replays to the run's own trajectories, and a bag
without odometry through scan-matching odometry (a CARMEN log's bag: test_carmen_run)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from acslam.cli import cli
from acslam.config import AlgorithmsConfig
from acslam.geometry import wrap_angles
from acslam.grid import OCCUPIED
from acslam.messages import LidarScan, RobotMessage
from acslam.pipeline.snapshot import Snapshot
from acslam.replay.outputs import PosedScans, build_map
from acslam.replay.rosbag import replay_bag, run_rosbag
from acslam.ros2 import convert
from acslam.ros2.bag import BagReader, BagWriter
from acslam.ros2.record import BagRecorder
from acslam.runner import RunHooks, run_exploration
from acslam.scenario import load_scenario
from acslam.slam.localizer import Isam2Localizer
from acslam.sources.recorded import RecordedSource
from acslam.trajectory import read_tum

RUN_S = 15.0


@pytest.mark.parametrize("command", [["slam", "rosbag"], ["convert"], ["convert", "carmen"]])
def test_commands_have_help(command: list[str]) -> None:
    result = CliRunner().invoke(cli, [*command, "--help"])
    assert result.exit_code == 0, result.output


def _signature(batch: list[RobotMessage]) -> list[tuple[str, int, float]]:
    return [(type(m).__name__, m.robot_id, round(m.stamp, 6)) for m in batch]


def test_a_recorded_run_replays_to_its_own_trajectories(
    tiny_scenario: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    """Two robots explore for 15 s with ``--record``'s recorder on; the bag replays in the
    batches the server received, searching for loop closures in the same batches, and,
    stopping where the run stopped (no final loop search and settling, which a live run
    never does), to the run's keyframe trajectories, to 5 mm and 5 mrad.

    Not closer: the bag holds ranges and landmark points as float32, the run had them as
    float64. The odometry calibration turns that into turn-scale estimates 1e-3 apart by
    the end of the run, and the last keyframes of a robot 3 mm apart (all others within
    0.3 mm), depending on when the closures entered."""
    loop_searches: dict[int, list[bool]] = {}
    optimize = Isam2Localizer.optimize

    def recording_optimize(self: Isam2Localizer, close_loops: bool) -> None:
        loop_searches.setdefault(id(self), []).append(close_loops)
        optimize(self, close_loops)

    monkeypatch.setattr(Isam2Localizer, "optimize", recording_optimize)
    scenario = load_scenario(tiny_scenario, robots=2)
    bag_path = tmp_path / "run.mcap"
    recorder = BagRecorder(bag_path, scenario)
    received = []

    def step(snapshot: Snapshot, messages: list[RobotMessage]) -> None:
        received.append(_signature(messages))
        recorder.on_step(snapshot, messages)

    hooks = RunHooks(on_step=step, on_finish=recorder.on_finish)
    run_exploration(scenario, tmp_path / "run", RUN_S, hooks=hooks)

    with BagReader(bag_path) as bag:
        topics = bag.topics
    assert topics["/map"] == "nav_msgs/msg/OccupancyGrid"
    for name in ("robot_0", "robot_1"):
        assert topics[f"/{name}/scan"] == "sensor_msgs/msg/LaserScan"
        assert topics[f"/{name}/odom"] == topics[f"/{name}/ground_truth"] == "nav_msgs/msg/Odometry"
        assert topics[f"/{name}/tf"] == topics[f"/{name}/tf_static"] == "tf2_msgs/msg/TFMessage"
        assert topics[f"/{name}/cmd_vel"] == "geometry_msgs/msg/Twist"
        assert topics[f"/{name}/landmarks"] == "sensor_msgs/msg/PointCloud2"

    with BagReader(bag_path) as bag:
        replay = replay_bag(bag, namespaces=["robot_0", "robot_1"], finish=False)
    period_s = scenario.config.algorithms.planning.control_period_s
    source = RecordedSource(replay.messages, period_s, replay.start_s)
    replayed = []
    while not source.finished:
        replayed.append(_signature(source.receive()))
        source.advance()
    assert replay.start_s == 0.0
    assert replayed == received[: len(replayed)] and len(replayed) >= RUN_S / period_s - 1
    run_searches, replay_searches = loop_searches.values()
    assert any(replay_searches) and replay_searches == run_searches[: len(replay_searches)]

    for robot in (0, 1):
        name = f"robot_{robot}"
        stamps, poses = read_tum(tmp_path / "run" / "trajectories" / f"{name}.estimated.tum")
        replay_stamps, replay_poses = replay.replayed.localizer.trajectory(robot)
        assert len(stamps) >= 10 and np.allclose(stamps, replay_stamps, atol=1e-6)
        error_m = np.hypot(*(poses[:, :2] - replay_poses[:, :2]).T)
        print(f"{name}: {len(stamps)} keyframes, max difference {error_m.max() * 1e3:.4f} mm")
        assert error_m.max() < 5e-3
        assert np.abs(wrap_angles(poses[:, 2] - replay_poses[:, 2])).max() < 5e-3
        assert np.hypot(*np.ptp(poses[:, :2], axis=0)) > 1.0  # the robot went somewhere


def _first_scans(source: Path, out: Path, count: int) -> None:
    """The first ``count`` scans of a bag, alone in an MCAP file."""
    with BagReader(source) as bag, BagWriter(out) as written:
        for item, _ in zip(bag.messages(["/scan"]), range(count), strict=False):
            written.write("/scan", item.message, convert.header_stamp_s(item.message))


def _on_walls(scans: list[LidarScan], poses: np.ndarray) -> float:
    """The share of beam endpoints, at ``poses``, on occupied cells of the map the scans
    make at those poses: near 1 where the poses are right, low where they smear walls."""
    values, spec = build_map(PosedScans(scans, list(poses), []), AlgorithmsConfig())
    on_walls = []
    for scan, pose in zip(scans, poses, strict=True):
        hit = np.isfinite(scan.ranges) & (scan.ranges > 0)
        angles = scan.angles[hit] + pose[2]
        ends = pose[:2] + scan.ranges[hit, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        rows, cols = spec.world_to_cell(ends).T
        on_walls.append(values[rows, cols] == OCCUPIED)
    return float(np.mean(np.concatenate(on_walls)))


def test_a_bag_without_odometry_gets_scan_matching_odometry(
    shared_dataset: Callable[[str], Path], tmp_path: Path
) -> None:
    """The first 150 scans of scan_tools_demo.bag (a laser moved ~2 m and turned ~4 rad by
    hand, no odometry, no tf): every scan posed, and the poses found explain the scans far
    better than standing still does."""
    bag_path = tmp_path / "scans.mcap"
    _first_scans(shared_dataset("datasets/rosbag_samples/scan_tools_demo.bag"), bag_path, 150)
    metrics = run_rosbag(bag_path, tmp_path / "out", odometry_map=False)
    robot = metrics["robots"]["/"]
    assert robot["odometry"] == "scan matching"
    assert robot["scans_used"] == robot["scans"] == 150
    _, poses = read_tum(tmp_path / "out" / "trajectory.tum")
    with BagReader(bag_path) as bag:
        scans = [convert.laser_scan(i.message, 0, 0.0) for i in bag.messages(["/scan"])]
    moving, still = _on_walls(scans, poses), _on_walls(scans, np.zeros_like(poses))
    print(f"beam endpoints on walls: {moving:.2f} at the poses found, {still:.2f} standing still")
    assert moving > 0.6 and moving > 2 * still


@pytest.mark.slow
def test_the_whole_ros1_scan_bag_replays(shared_dataset: Callable[[str], Path], tmp_path: Path):
    """All 360 scans of scan_tools_demo.bag, read as the ROS 1 bag it is, through the CLI."""
    bag_path = shared_dataset("datasets/rosbag_samples/scan_tools_demo.bag")
    result = CliRunner().invoke(cli, ["slam", "rosbag", str(bag_path), "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    _, poses = read_tum(tmp_path / "trajectory.tum")
    with BagReader(bag_path) as bag:
        scans = [convert.laser_scan(i.message, 0, 0.0) for i in bag.messages(["/scan"])]
    assert len(poses) == len(scans) == 360
    moving, still = _on_walls(scans, poses), _on_walls(scans, np.zeros_like(poses))
    print(f"beam endpoints on walls: {moving:.2f} at the poses found, {still:.2f} standing still")
    assert moving > 0.6 and moving > 2 * still
