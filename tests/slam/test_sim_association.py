"""Data association in simulation: three robots drive scripted rectangle loops in a room.

The world is a room with a pillar, camera landmarks near every wall (``place_landmarks``)
and the simulator's own odometry (bias + scale errors), camera (4 m, 70 deg, 3 cm) and
clock. The robots are driven by a scripted waypoint controller on their *true* pose (the
test is about the back end, not the planner); the back end sees only the messages. The
simulator's ground-truth landmark ids score the association, never feed it.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from acslam.config import (
    LandmarkConfig,
    LidarConfig,
    RobotsConfig,
    SensorsConfig,
    SimConfig,
    SlamConfig,
)
from acslam.eval.metrics import pairwise_precision_recall
from acslam.geometry import compose
from acslam.grid import GridSpec
from acslam.messages import LandmarkObservations, OdometryIncrement, VelocityCommand
from acslam.sim.simulator import Simulator
from acslam.slam.backend import SlamBackend
from acslam.worlds.landmarks import place_landmarks
from acslam.worlds.world import World

RES = 0.05
CORNERS = np.array([[1.0, 1.0], [7.0, 1.0], [7.0, 5.0], [1.0, 5.0]])
STARTS = np.array([[1.0, 1.0, 0.0], [7.0, 5.0, math.pi], [7.0, 1.0, math.pi / 2]])
FIRST_TARGET = [1, 3, 2]  # each robot drives the same counter-clockwise loop
DURATION_S = 130.0  # one full 20 m loop (~110 s with the turns) and a little more
UPDATE_PERIOD_S = 0.5


def _room() -> World:
    """8 m x 6 m room with a 4 m x 2 m pillar in the middle: a 1.5-2 m wide ring corridor."""
    spec = GridSpec(-0.5, -0.5, RES, int(7.0 / RES), int(9.0 / RES))
    y, x = np.mgrid[0 : spec.rows, 0 : spec.cols] * RES - 0.5
    occupied = (x < 0.0) | (x > 8.0) | (y < 0.0) | (y > 6.0)
    occupied |= (x > 2.0) & (x < 6.0) & (y > 2.0) & (y < 4.0)
    return World("room", spec, occupied)


def _command(robot_id: int, pose: np.ndarray, target: np.ndarray, stamp: float):
    dx, dy = target - pose[:2]
    error = (math.atan2(dy, dx) - pose[2] + math.pi) % (2 * math.pi) - math.pi
    if abs(error) > 0.15:
        return VelocityCommand(robot_id, stamp, 0.0, float(np.clip(2.0 * error, -1.0, 1.0)))
    return VelocityCommand(robot_id, stamp, 0.2, float(2.0 * error))


@cache
def _run(outlier_fraction: float, seed: int = 3) -> dict:
    world = _room()
    landmarks = place_landmarks(
        world, LandmarkConfig(density_per_m2=1.0), np.random.default_rng(seed)
    )
    sensors = SensorsConfig(lidar=LidarConfig(rate_hz=0.1, beams=1))
    sim = Simulator(world, STARTS, landmarks, RobotsConfig(), sensors, SimConfig(), seed)
    config = SlamConfig(landmark_sigma_m=0.03)  # the simulated camera's noise
    backend = SlamBackend(config, {i: s for i, s in enumerate(STARTS)})
    rng = np.random.default_rng(seed + 100)
    targets = list(FIRST_TARGET)
    dead_reckoning = {i: {0.0: s.copy()} for i, s in enumerate(STARTS)}
    last_dr = {i: s.copy() for i, s in enumerate(STARTS)}
    truth_ids, est_ids = [], []
    next_update = UPDATE_PERIOD_S
    commands: list[VelocityCommand] = []
    while sim.time_s < DURATION_S:
        poses = sim.ground_truth.poses()
        commands = []
        for i, pose in enumerate(poses):
            if np.linalg.norm(CORNERS[targets[i]] - pose[:2]) < 0.1:
                targets[i] = (targets[i] + 1) % len(CORNERS)
            commands.append(_command(i, pose, CORNERS[targets[i]], sim.time_s))
        for msg in sim.step(commands):
            if isinstance(msg, OdometryIncrement):
                backend.add_odometry(msg)
                last_dr[msg.robot_id] = compose(last_dr[msg.robot_id], msg.delta)
                dead_reckoning[msg.robot_id][round(msg.stamp, 6)] = last_dr[msg.robot_id]
            elif isinstance(msg, LandmarkObservations) and len(msg.points):
                ids = np.array(sim.ground_truth.observed_landmark_ids(msg.robot_id, msg.stamp))
                points = np.array(msg.points, dtype=float)
                wrong = rng.random(len(points)) < outlier_fraction
                for n in np.flatnonzero(wrong):
                    rho, bearing = rng.uniform(0.3, 4.0), rng.uniform(-0.6, 0.6)
                    points[n] = [rho * math.cos(bearing), rho * math.sin(bearing), rng.random()]
                results = backend.add_landmarks(
                    LandmarkObservations(msg.robot_id, msg.stamp, points)
                )
                for true_id, is_wrong, result in zip(ids, wrong, results, strict=True):
                    if result.landmark >= 0:
                        truth_ids.append(-1 - len(truth_ids) if is_wrong else int(true_id))
                        est_ids.append(result.landmark)
        if sim.time_s >= next_update:
            backend.update()
            next_update += UPDATE_PERIOD_S
    backend.update(extra_iterations=3)

    slam_err, dr_err, per_robot = [], [], {}
    for i in range(len(STARTS)):
        stamps, poses = backend.trajectory(i)
        truth = sim.ground_truth.trajectory(i)
        rows = np.searchsorted(truth[:, 0], stamps - 1e-9)
        dr = np.array([dead_reckoning[i][round(s, 6)] for s in stamps])
        e_slam = np.linalg.norm(poses[:, :2] - truth[rows, 1:3], axis=1)
        e_dr = np.linalg.norm(dr[:, :2] - truth[rows, 1:3], axis=1)
        per_robot[i] = (float(np.sqrt(np.mean(e_slam**2))), float(np.sqrt(np.mean(e_dr**2))))
        slam_err.append(e_slam)
        dr_err.append(e_dr)
    precision, recall = pairwise_precision_recall(np.array(truth_ids), np.array(est_ids))
    lms = backend.landmarks()
    nearest = np.linalg.norm(lms[:, None, :2] - landmarks[None, :, :2], axis=2).min(axis=1)
    return {
        "rmse": float(np.sqrt(np.mean(np.concatenate(slam_err) ** 2))),
        "dr_rmse": float(np.sqrt(np.mean(np.concatenate(dr_err) ** 2))),
        "per_robot": per_robot,
        "precision": precision,
        "recall": recall,
        "landmarks": len(lms),
        "true_landmarks": len(landmarks),
        "landmark_rmse": float(np.sqrt(np.mean(nearest**2))),
    }


def test_three_robot_loops_beat_dead_reckoning_five_fold() -> None:
    """Position RMSE <= 0.05 m and <= 1/5 of dead reckoning's, precision >= 0.95."""
    run = _run(0.0)
    print(run)
    assert run["rmse"] <= 0.05, run
    assert run["rmse"] <= run["dr_rmse"] / 5, run
    for slam, dr in run["per_robot"].values():
        assert slam <= dr / 5, run
    assert run["precision"] >= 0.95, run


def test_five_percent_wrong_measurements_cost_at_most_half_the_accuracy() -> None:
    """5 % of the points replaced by random points in the camera's field of view."""
    clean, dirty = _run(0.0), _run(0.05)
    print(clean, dirty)
    assert dirty["rmse"] <= 1.5 * clean["rmse"], (clean, dirty)


if __name__ == "__main__":  # pragma: no cover
    pytest.main([__file__, "-s"])
