"""The simulator: sensor rates, determinism, collisions and the ground-truth boundary."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
from simtest_worlds import RES_M, box_world

from acslam.config import (
    CameraConfig,
    LidarConfig,
    OdometryConfig,
    RobotsConfig,
    SensorsConfig,
    SimConfig,
)
from acslam.errors import ConfigError
from acslam.geometry import compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, VelocityCommand
from acslam.sim.simulator import Simulator

FAST = RobotsConfig(max_v_mps=2.0, max_acc_v_mps2=100.0)
NOISELESS = SensorsConfig(
    odometry=OdometryConfig(
        bias_v_std_mps=0.0, bias_omega_std_radps=0.0, scale_v_std=0.0, scale_omega_std=0.0
    ),
    lidar=LidarConfig(range_noise_std_m=0.0, range_noise_rel=0.0, angle_noise_std_rad=0.0),
    camera=CameraConfig(noise_std_m=0.0),
)
SMALL_LIDAR = SensorsConfig(lidar=LidarConfig(beams=90))


def _landmarks(world_width_m: float, count: int = 40) -> np.ndarray:
    rng = np.random.default_rng(0)
    return np.column_stack(
        [rng.uniform(0.2, world_width_m - 0.2, count), rng.uniform(0.2, 3.8, count),
         rng.uniform(0.1, 1.0, count)]
    )  # fmt: skip


def _scripted(sim: Simulator, robot_ids: range, steps: int) -> list:
    """Forward speed with a sinusoidal turn rate, different per robot."""
    log = []
    for _ in range(steps):
        t = sim.time_s
        commands = [VelocityCommand(i, t, 0.2, 1.2 * math.sin(0.7 * t + i)) for i in robot_ids]
        log.extend(sim.step(commands))
    return log


def _as_tuple(message: object) -> tuple:
    return tuple(
        value.tobytes() if isinstance(value, np.ndarray) else value
        for value in dataclasses.astuple(message)
    )


def test_sensor_rates_stamps_and_order() -> None:
    world = box_world(6.0, 4.0)
    starts = np.array([[1.0, 1.0, 0.0], [4.0, 3.0, math.pi]])
    sim = Simulator(world, starts, _landmarks(6.0), RobotsConfig(), SMALL_LIDAR, SimConfig(), 0)
    log = _scripted(sim, range(2), 50)
    assert math.isclose(sim.time_s, 1.0)
    for i in range(2):
        mine = [m for m in log if m.robot_id == i]
        odometry = [m for m in mine if isinstance(m, OdometryIncrement)]
        assert len(odometry) == 20
        assert len([m for m in mine if isinstance(m, LidarScan)]) == 10
        assert len([m for m in mine if isinstance(m, LandmarkObservations)]) == 5
        assert odometry[0].start_stamp == 0.0
        for previous, current in itertools.pairwise(odometry):
            assert current.start_stamp == previous.stamp
        # 0.05 s is not a multiple of dt = 0.02 s: each fires at the first step past due.
        due = 0.05 * np.arange(1, 21)
        stamps = np.array([m.stamp for m in odometry])
        assert ((stamps >= due - 1e-9) & (stamps < due + 0.02)).all()
    kinds = [OdometryIncrement, LidarScan, LandmarkObservations]
    keys = [(m.stamp, m.robot_id, kinds.index(type(m))) for m in log]
    assert keys == sorted(keys)


def test_noise_free_odometry_composes_to_ground_truth_through_a_collision() -> None:
    world = box_world(6.0, 4.0)
    sim = Simulator(
        world, np.array([[1.0, 2.0, 0.3]]), np.zeros((0, 3)), FAST, NOISELESS, SimConfig(), 0
    )
    log = []
    for k in range(250):  # curves, then drives into the right-hand wall
        log.extend(sim.step([VelocityCommand(0, sim.time_s, 1.5, 0.5 * math.cos(0.05 * k))]))
    assert sim.ground_truth.collisions[0, 0] >= 1
    trajectory = sim.ground_truth.trajectory(0)
    pose = trajectory[0, 1:]
    for increment in (m for m in log if isinstance(m, OdometryIncrement)):
        pose = compose(pose, increment.delta)
        row = trajectory[np.argmin(np.abs(trajectory[:, 0] - increment.stamp))]
        assert row[0] == increment.stamp
        assert np.allclose(pose[:2], row[1:3], rtol=0, atol=1e-9)
        assert abs(math.remainder(pose[2] - row[3], 2 * math.pi)) < 1e-9


def test_same_seed_same_messages_and_an_extra_robot_changes_nothing_else() -> None:
    # Two rooms split by a full wall at x in [4.0, 4.05); robot 3 lives in the right room.
    world = box_world(8.0, 4.0, wall_cols=(80,))
    starts = np.array([[1.0, 1.0, 0.0], [2.5, 3.0, -1.0], [1.0, 3.0, 0.5], [6.0, 2.0, 1.0]])
    landmarks = _landmarks(8.0)

    def run(robot_count: int, seed: int) -> list[tuple]:
        sim = Simulator(
            world, starts[:robot_count], landmarks, RobotsConfig(), SMALL_LIDAR, SimConfig(), seed
        )
        return [_as_tuple(m) for m in _scripted(sim, range(robot_count), 500)]

    first = run(3, seed=5)
    assert first == run(3, seed=5)
    assert first != run(3, seed=6)
    with_fourth = [m for m in run(4, seed=5) if m[0] != 3]
    assert first == with_fourth


@pytest.mark.parametrize("limits", [FAST, RobotsConfig()], ids=["2mps", "default"])
def test_robot_at_max_speed_never_crosses_a_thin_wall(limits: RobotsConfig) -> None:
    world = box_world(6.0, 4.0, wall_cols=(60,))  # wall face at x = 3.0
    sim = Simulator(
        world, np.array([[2.4, 2.0, 0.0]]), np.zeros((0, 3)), limits, NOISELESS, SimConfig(), 0
    )
    for _ in range(250):  # pushes on long after contact (creeping, at default limits)
        sim.step([VelocityCommand(0, sim.time_s, limits.max_v_mps, 0.0)])
    x = sim.ground_truth.trajectory(0)[:, 1]
    # The disc never overlaps the wall face and stops within one substep (half a cell) of it.
    assert x.max() + limits.radius_m <= 3.0 + 1e-12
    assert x.max() + limits.radius_m >= 3.0 - 0.5 * RES_M
    assert np.ptp(x[-50:]) < 1e-12  # stopped
    assert sim.ground_truth.collisions.tolist() == [[1, 0]]


def test_head_on_robots_stop_apart_and_count_one_contact_each() -> None:
    world = box_world(6.0, 4.0)
    starts = np.array([[1.0, 2.0, 0.0], [3.0, 2.0, math.pi]])
    sim = Simulator(world, starts, np.zeros((0, 3)), FAST, NOISELESS, SimConfig(), 0)
    for _ in range(100):
        t = sim.time_s
        sim.step({0: VelocityCommand(0, t, 2.0, 0.0), 1: VelocityCommand(1, t, 2.0, 0.0)})
    poses = sim.ground_truth.poses()
    assert np.hypot(*(poses[0, :2] - poses[1, :2])) >= 2 * FAST.radius_m
    assert sim.ground_truth.collisions.tolist() == [[0, 1], [0, 1]]


def test_contact_counts_again_after_backing_off() -> None:
    world = box_world(6.0, 4.0, wall_cols=(60,))
    sim = Simulator(
        world, np.array([[2.0, 2.0, 0.0]]), np.zeros((0, 3)), FAST, NOISELESS, SimConfig(), 0
    )
    for v, steps in ((1.0, 60), (-1.0, 30), (1.0, 60)):
        for _ in range(steps):
            sim.step([VelocityCommand(0, sim.time_s, v, 0.0)])
    assert sim.ground_truth.collisions.tolist() == [[2, 0]]


def test_camera_ground_truth_goes_to_the_side_channel_only() -> None:
    world = box_world(6.0, 4.0)
    landmarks = _landmarks(6.0)
    sim = Simulator(
        world, np.array([[1.0, 2.0, 0.0]]), landmarks, RobotsConfig(), NOISELESS, SimConfig(), 0
    )
    log = _scripted(sim, range(1), 50)
    cameras = [m for m in log if isinstance(m, LandmarkObservations)]
    assert len(cameras) == len(sim.ground_truth.camera_log) == 5
    for message in cameras:
        ids = sim.ground_truth.observed_landmark_ids(0, message.stamp)
        assert len(ids) == len(message.points)
    assert any(len(m.points) for m in cameras)
    fields = {f.name for f in dataclasses.fields(LandmarkObservations)}
    # ``ids`` are identities a real sensor recognises itself (fiducials, barcodes); the
    # simulated camera recognises none, so the true ids stay in the side channel.
    assert fields == {"robot_id", "stamp", "points", "descriptors", "ids"}
    assert all(m.ids is None for m in cameras)
    for kind in (OdometryIncrement, LidarScan, LandmarkObservations, VelocityCommand):
        names = {f.name for f in dataclasses.fields(kind)}
        assert not names & {"landmark_ids", "true_pose", "pose", "ground_truth"}


def test_invalid_starts_and_commands_are_rejected() -> None:
    world = box_world(6.0, 4.0)
    args = (np.zeros((0, 3)), RobotsConfig(), SensorsConfig(), SimConfig(), 0)
    with pytest.raises(ConfigError, match=r"robots.starts\[0\]"):
        Simulator(world, np.array([[0.05, 2.0, 0.0]]), *args)
    with pytest.raises(ConfigError, match=r"robots.starts\[1\]"):
        Simulator(world, np.array([[1.0, 2.0, 0.0], [1.1, 2.0, 0.0]]), *args)
    sim = Simulator(world, np.array([[1.0, 2.0, 0.0]]), *args)
    with pytest.raises(ValueError, match="no such robot"):
        sim.step([VelocityCommand(1, 0.0, 0.1, 0.0)])
