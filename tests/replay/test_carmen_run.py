"""`acslam slam carmen` end to end: a synthetic CARMEN log from the simulator, and Intel.

The synthetic log: one robot drives two laps of the ring corridor round a pillar (8 m x
6 m room) on a scripted waypoint controller that reads the *true* pose; the simulator's
odometry (bias and scale errors) is dead-reckoned into absolute ``ODOM`` poses and its
LiDAR, set up as a CARMEN front laser (181 beams over 180 deg, SICK-like 1 cm noise),
written as ``FLASER`` lines whose laser pose is the odometry pose moved by the laser's
mount. The file also holds a truncated line and two FLASER lines swapped (logger time
steps back), as real logs do.

The same logs, written as ROS 2 bags by ``acslam convert carmen``, replay through
``acslam slam rosbag`` to the trajectories ``acslam slam carmen`` finds.
"""

from __future__ import annotations

import json
import math
import subprocess
from collections.abc import Callable
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from acslam.cli import cli
from acslam.config import LidarConfig, RobotsConfig, SensorsConfig, SimConfig
from acslam.datasets.carmen import CarmenWarning, laser_offset, read_carmen
from acslam.geometry import compose, wrap_angles
from acslam.grid import GridSpec
from acslam.messages import LidarScan, OdometryIncrement, VelocityCommand
from acslam.replay.carmen import run_carmen
from acslam.sim.simulator import Simulator
from acslam.trajectory import read_tum
from acslam.worlds.mapio import load_map
from acslam.worlds.world import World

RES = 0.05
CORNERS = np.array([[1.0, 1.0], [7.0, 1.0], [7.0, 5.0], [1.0, 5.0]])
START = np.array([1.0, 1.0, 0.0])
LAPS_S = 240.0  # two 20 m laps at 0.2 m/s with the turns
IPC_OFFSET_S = 1.0e9  # ipc stamps are unix time; logger stamps start at 0
FRONT_LASER = LidarConfig(
    rate_hz=5.0,
    beams=181,
    fov_rad=math.pi,
    range_max_m=8.0,
    range_noise_std_m=0.01,
    range_noise_rel=0.0,
)


def _room() -> World:
    """8 m x 6 m room with a 4 m x 2 m pillar: a 1.5-2 m wide ring corridor."""
    spec = GridSpec(-0.5, -0.5, RES, int(7.0 / RES), int(9.0 / RES))
    y, x = np.mgrid[0 : spec.rows, 0 : spec.cols] * RES - 0.5
    occupied = (x < 0.0) | (x > 8.0) | (y < 0.0) | (y > 6.0)
    occupied |= (x > 2.0) & (x < 6.0) & (y > 2.0) & (y < 4.0)
    return World("room", spec, occupied)


def _command(pose: np.ndarray, target: np.ndarray, stamp: float) -> VelocityCommand:
    dx, dy = target - pose[:2]
    error = (math.atan2(dy, dx) - pose[2] + math.pi) % (2 * math.pi) - math.pi
    if abs(error) > 0.15:
        return VelocityCommand(0, stamp, 0.0, float(np.clip(2.0 * error, -1.0, 1.0)))
    return VelocityCommand(0, stamp, 0.2, float(2.0 * error))


def _pose_text(pose: np.ndarray) -> str:
    return f"{pose[0]:.6f} {pose[1]:.6f} {pose[2]:.6f}"


@cache
def _synthetic_log(
    seconds: float = LAPS_S, laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> tuple[list[str], np.ndarray]:
    """CARMEN lines and the true (N, 4) ``[t, x, y, theta]`` track of the simulator."""
    sensors = SensorsConfig(lidar=FRONT_LASER)
    sim = Simulator(
        _room(), START[None], np.zeros((0, 3)), RobotsConfig(), sensors, SimConfig(), seed=5
    )
    lines = ["# synthetic CARMEN log", f"PARAM robot_frontlaser_offset {laser_offset[0]} nohost 0"]
    odometry = START.copy()
    target = 1
    while sim.time_s < seconds:
        pose = sim.ground_truth.poses()[0]
        if np.linalg.norm(CORNERS[target] - pose[:2]) < 0.1:
            target = (target + 1) % len(CORNERS)
        for msg in sim.step([_command(pose, CORNERS[target], sim.time_s)]):
            tail = f"{IPC_OFFSET_S + msg.stamp:.6f} simhost {msg.stamp:.6f}"
            if isinstance(msg, OdometryIncrement):
                odometry = compose(odometry, msg.delta)
                lines.append(f"ODOM {_pose_text(odometry)} 0 0 0 {tail}")
            elif isinstance(msg, LidarScan):
                ranges = " ".join(f"{r:.3f}" if np.isfinite(r) else "81.910" for r in msg.ranges)
                poses = f"{_pose_text(compose(odometry, laser_offset))} {_pose_text(odometry)}"
                lines.append(f"FLASER {len(msg.ranges)} {ranges} {poses} {tail}")
    return lines, sim.ground_truth.trajectory(0)


def _write_log(path: Path) -> tuple[list[str], np.ndarray]:
    """The synthetic log with a truncated line and two FLASER lines out of time order."""
    lines, truth = _synthetic_log()
    lines = list(lines)
    flaser = [n for n, text in enumerate(lines) if text.startswith("FLASER")]
    a, b = flaser[300], flaser[301]
    lines[a], lines[b] = lines[b], lines[a]
    lines.insert(flaser[500], lines[flaser[500]][:200])  # truncated: becomes its own line
    path.write_text("\n".join(lines) + "\n", encoding="ascii")
    return lines, truth


def _position_errors(stamps: np.ndarray, poses: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Distance to the true pose of the simulator step at each (ipc) stamp."""
    rows = np.searchsorted(truth[:, 0], stamps - IPC_OFFSET_S - 1e-6)
    return np.hypot(*(poses[:, :2] - truth[rows, 1:3]).T)


def test_synthetic_log_trajectory_map_and_metrics(tmp_path: Path) -> None:
    log_path = tmp_path / "synthetic.clf"
    lines, truth = _write_log(log_path)
    with pytest.warns(CarmenWarning, match=r"synthetic\.clf:\d+: skipped FLASER"):
        metrics = run_carmen(log_path, tmp_path / "out")
    out = tmp_path / "out"
    for name in ("trajectory.tum", "map.yaml", "map.pgm", "map.png", "odometry_vs_slam.png"):
        assert (out / name).is_file(), name

    # One pose per well-formed FLASER line, in file order, with its exact ipc stamp.
    expected = [
        float(text.split()[-3])
        for text in lines
        if text.startswith("FLASER") and len(text.split()) == 181 + 11
    ]
    stamps, poses = read_tum(out / "trajectory.tum")
    assert len(stamps) == len(expected) and np.array_equal(stamps, np.round(expected, 9))
    assert (np.diff(stamps) < 0).sum() == 1  # the swapped pair, kept in file order

    truncated = next(n for n, text in enumerate(lines, start=1) if len(text) == 200)
    assert metrics["skipped_lines"] == {"count": 1, "lines": [truncated]}
    assert metrics == json.loads((out / "metrics.json").read_text())
    # Replays say what produced them, as runs do.
    assert set(metrics["provenance"]) == {"acslam_version", "commit", "command", "date_utc"}
    assert metrics["scans_used"] == len(expected)
    assert metrics["loop_closures"]["accepted"] >= 1

    # Accuracy at every FLASER stamp. The bound, 0.1 m (two map cells), keeps walls single
    # in the map; the simulator's odometry drifts ~1 m over the two laps, far beyond it.
    slam_error = _position_errors(stamps, poses, truth)
    well_formed = [t for t in lines if t.startswith("FLASER") and len(t.split()) == 181 + 11]
    odom = np.array([[float(v) for v in t.split()[-9:-6]] for t in well_formed])
    dead_reckoning_error = _position_errors(stamps, odom, truth)
    print(f"max error: SLAM {slam_error.max():.3f} m, odometry {dead_reckoning_error.max():.3f} m")
    assert dead_reckoning_error.max() > 0.5
    assert slam_error.max() < 0.1
    rows = np.searchsorted(truth[:, 0], stamps - IPC_OFFSET_S - 1e-6)
    assert np.abs(wrap_angles(poses[:, 2] - truth[rows, 3])).max() < 0.03


def test_cli_on_a_corrupt_log_is_one_line_error(tmp_path: Path) -> None:
    broken = tmp_path / "broken.clf.bz2"
    broken.write_bytes(b"BZh9 this is not bzip2")
    result = subprocess.run(
        ["acslam", "slam", "carmen", str(broken), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.startswith(f"acslam: error: {broken}: cannot read log")
    assert "Traceback" not in result.stderr and result.stderr.count("\n") == 1


@pytest.mark.slow
def test_intel_lab(shared_dataset: Callable[[str], Path], tmp_path: Path) -> None:
    """The real Intel Research Lab log (45 min): every scan posed, loops closed, faster
    than real time, and a map of the lab's size.

    The lab's outer walls span 28.7 m x 29.1 m in the map of the GMapping-corrected log
    of the same folder; the odometry-only map smears over ~80 m. The occupied cells of our
    map (0.5-99.5 % quantiles) must span 27-31 m in both axes.
    """
    log = shared_dataset("datasets/intel_lab_carmen/intel.clf.bz2")
    metrics = run_carmen(log, tmp_path, odometry_map=False)
    assert metrics["scans_used"] == metrics["scans"] == 13631
    assert metrics["skipped_lines"]["count"] == 0
    assert metrics["loop_closures"]["accepted"] >= 500
    assert metrics["real_time_factor"] > 3.0  # ~19 on one idle core, ~9 on a busy one
    stamps, _ = read_tum(tmp_path / "trajectory.tum")
    assert len(stamps) == 13631
    cells, spec = load_map(tmp_path / "map.yaml")
    occupied = spec.cell_to_world(np.argwhere(cells == 100))
    span = np.diff(np.percentile(occupied, [0.5, 99.5], axis=0), axis=0)[0]
    assert ((span > 27.0) & (span < 31.0)).all(), span


def _carmen_and_bag(log_path: Path, out: Path) -> tuple[np.ndarray, np.ndarray, dict, dict]:
    """The laser pose of every FLASER line, in time order, by `slam carmen` and by `slam
    rosbag --algorithms carmen` of the log's `convert carmen` bag (its base poses moved to
    the laser by the log's mount); then both metrics."""
    carmen = run_carmen(log_path, out / "carmen", odometry_map=False)
    bag = out / "log.mcap"
    for command in (
        ["convert", "carmen", str(log_path), str(bag)],
        ["slam", "rosbag", str(bag), "--out", str(out / "bag"), "--algorithms", "carmen"],
    ):
        result = CliRunner().invoke(cli, command)
        assert result.exit_code == 0, result.output
    log = read_carmen(log_path)
    mount = laser_offset(log)
    in_file_order = sorted(log.scans, key=lambda record: record.line)
    in_time_order = sorted(
        range(len(in_file_order)), key=lambda k: (in_file_order[k].stamp_s, in_file_order[k].line)
    )
    _, carmen_poses = read_tum(out / "carmen" / "trajectory.tum")
    _, base_poses = read_tum(out / "bag" / "trajectory.tum")
    bag_poses = np.array([compose(pose, mount) for pose in base_poses])
    bag_metrics = json.loads((out / "bag" / "metrics.json").read_text())
    return carmen_poses[in_time_order], bag_poses, carmen, bag_metrics


TUM_PRECISION = 1e-8
"""Poses agree to this (m, rad) when equal: TUM files hold 9 decimals, and the bag's
trajectory is of the base, moved back to the laser here by the mount."""


def _assert_same_replay(log_path: Path, out: Path) -> np.ndarray:
    """`slam carmen` and `convert carmen` + `slam rosbag` play the same messages, so they
    give the same trajectory (to the files' precision) and the same figures; returns the
    position differences."""
    carmen_poses, bag_poses, carmen, bag = _carmen_and_bag(log_path, out)
    assert len(bag_poses) == len(carmen_poses) == carmen["scans_used"] == carmen["scans"]
    assert bag["robots"]["/"]["keyframes"] == carmen["keyframes"]
    assert bag["robots"]["/"]["mount_xytheta"] == carmen["laser_offset_xytheta"]
    for figure in ("scan_matching", "loop_closures", "log_duration_s", "map"):
        assert bag[figure] == carmen[figure], figure
    error_m = np.hypot(*(carmen_poses[:, :2] - bag_poses[:, :2]).T)
    yaw_error_rad = np.abs(wrap_angles(carmen_poses[:, 2] - bag_poses[:, 2]))
    print(
        f"{len(error_m)} scans, max difference {error_m.max():.2e} m, "
        f"{yaw_error_rad.max():.2e} rad; loop closures {carmen['loop_closures']}"
    )
    assert error_m.max() < TUM_PRECISION
    assert yaw_error_rad.max() < TUM_PRECISION
    return error_m


def test_a_synthetic_logs_bag_replays_like_the_log(tmp_path: Path) -> None:
    """110 s (loops closed) with the laser 10 cm off the base: `convert carmen` then `slam
    rosbag` poses every scan where `slam carmen` does."""
    lines, _ = _synthetic_log(110.0, (0.1, 0.02, 0.05))
    log_path = tmp_path / "log.clf"
    log_path.write_text("\n".join(lines) + "\n")
    _assert_same_replay(log_path, tmp_path)


@pytest.mark.slow
def test_intel_labs_bag_replays_like_the_log(
    shared_dataset: Callable[[str], Path], tmp_path: Path
) -> None:
    """Intel as a bag: all 13,631 scans posed where `slam carmen` poses them, over the whole
    45 min, with the same keyframes, loop closures and map. A SLAM with thresholds is not
    continuous in its inputs (a change far below the log's 1 cm can tip one of its
    accept/reject decisions), so this holds because both commands replay the same ROS
    messages."""
    log = shared_dataset("datasets/intel_lab_carmen/intel.clf.bz2")
    error_m = _assert_same_replay(log, tmp_path)
    assert len(error_m) == 13631
