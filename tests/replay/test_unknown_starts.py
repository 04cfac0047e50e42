"""`acslam slam rosbag --unknown-starts`: robots replayed each in its own frame, their maps
merged at the relative pose the recording's truth gives."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from acslam.cli import cli
from acslam.geometry import between
from acslam.ros2.record import BagRecorder
from acslam.runner import RunHooks, run_exploration
from acslam.scenario import load_scenario
from acslam.trajectory import read_tum


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two robots of thesis experiment 2 explore for 15 s with the recorder on."""
    folder = tmp_path_factory.mktemp("unknown-starts")
    scenario = load_scenario("thesis-exp2", robots=2)
    recorder = BagRecorder(folder / "run.mcap", scenario)
    hooks = RunHooks(on_step=recorder.on_step, on_finish=recorder.on_finish)
    run_exploration(scenario, folder / "run", 15.0, hooks=hooks)
    return folder / "run.mcap", folder / "run"


def test_robots_replayed_in_their_own_frames_merge_at_their_true_relative_start(
    recorded: tuple[Path, Path], tmp_path: Path
) -> None:
    bag, run = recorded
    out = tmp_path / "out"
    arguments = ["slam", "rosbag", str(bag), "--robots", "robot_0,robot_1", "--unknown-starts"]
    result = CliRunner().invoke(cli, [*arguments, "--no-finish", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "robot_1: merged at" in result.output
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["relative_starts"] == "unknown"
    robot = metrics["robots"]["robot_1"]
    assert robot["merged"] and robot["merge"]["accepted"]
    # The recording's odometry starts at the true start poses, so it gives the truth.
    assert robot["merge_error_vs_odometry"]["translation_m"] <= 0.1
    assert robot["merge_error_vs_odometry"]["rotation_rad"] <= 0.03
    # Each robot starts at the origin of its own frame ...
    assert metrics["robots"]["robot_0"]["start_xytheta"] == pytest.approx([0.0, 0.0, 0.0])
    # ... and robot_1's trajectory, carried into robot_0's frame, follows its true path
    # seen from robot_0's true start.
    _, truth_0 = read_tum(run / "trajectories" / "robot_0.groundtruth.tum")
    stamps_1, truth_1 = read_tum(run / "trajectories" / "robot_1.groundtruth.tum")
    merged_stamps, merged = read_tum(out / "trajectory_robot_1.tum")
    origin = truth_0[0]
    at = np.searchsorted(stamps_1, merged_stamps - 1e-6)
    expected = np.array([between(origin, truth_1[k]) for k in at])
    error_m = np.hypot(*(merged[:, :2] - expected[:, :2]).T)
    assert np.sqrt(np.mean(error_m**2)) <= 0.1
    assert (out / "merge_robot_1.png").stat().st_size > 0
    assert not (out / "map_robot_1.yaml").exists()
    # The same bag gives the same merge.
    again = CliRunner().invoke(cli, [*arguments, "--no-finish", "--out", str(tmp_path / "again")])
    assert again.exit_code == 0
    repeated = json.loads((tmp_path / "again" / "metrics.json").read_text())
    assert repeated["robots"]["robot_1"]["merge"] == robot["merge"]
