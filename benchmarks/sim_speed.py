"""Simulator speed: simulated seconds per wall-clock second (real-time factor).

N robots drive a scripted motion (constant forward speed, sinusoidal turn rate; robots
that hit a wall just stop) with every sensor at its default rate and no server. Also
times a plain-NumPy ray cast of the same scans, for a reference ratio.

    python benchmarks/sim_speed.py [--sim-seconds 60]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from acslam.config import (
    DungeonWorld,
    LandmarkConfig,
    RobotsConfig,
    SensorsConfig,
    SimConfig,
    ThesisWorld,
)
from acslam.messages import VelocityCommand
from acslam.seeding import Stream, rng
from acslam.sim.lidar import beam_angles
from acslam.sim.simulator import Simulator
from acslam.worlds.generators import build_world
from acslam.worlds.landmarks import place_landmarks
from acslam.worlds.world import World


def scripted_commands(time_s: float, robot_count: int, v_mps: float) -> list[VelocityCommand]:
    return [
        VelocityCommand(i, time_s, v_mps, 1.5 * math.sin(0.4 * time_s + 1.3 * i))
        for i in range(robot_count)
    ]


def real_time_factor(world: World, robot_count: int, sim_seconds: float) -> tuple[float, float]:
    """(RTF, wall seconds) of ``sim_seconds`` of simulation after a one-second warm-up."""
    robots = RobotsConfig()
    landmarks = place_landmarks(world, LandmarkConfig(), rng(0, Stream.LANDMARKS))
    sim = Simulator(
        world,
        world.default_starts[:robot_count],
        landmarks,
        robots,
        SensorsConfig(),
        SimConfig(),
        seed=0,
    )
    steps = round(sim_seconds / SimConfig().dt_s)
    for _ in range(round(1.0 / SimConfig().dt_s)):  # JIT compile / cache load
        sim.step(scripted_commands(sim.time_s, robot_count, robots.max_v_mps))
    start = time.perf_counter()
    for _ in range(steps):
        sim.step(scripted_commands(sim.time_s, robot_count, robots.max_v_mps))
    wall_s = time.perf_counter() - start
    return sim_seconds / wall_s, wall_s


def numpy_scan_seconds(world: World, pose: np.ndarray, repeats: int = 20) -> float:
    """Wall time of one default scan by sampling each ray every quarter cell in NumPy."""
    config = SensorsConfig().lidar
    spec = world.spec
    samples_m = np.arange(0.0, config.range_max_m, 0.25 * spec.resolution_m)
    angles = pose[2] + beam_angles(config)
    start = time.perf_counter()
    for _ in range(repeats):
        x = pose[0] + np.cos(angles)[:, None] * samples_m
        y = pose[1] + np.sin(angles)[:, None] * samples_m
        col = np.floor((x - spec.origin_x_m) / spec.resolution_m).astype(np.int64)
        row = np.floor((y - spec.origin_y_m) / spec.resolution_m).astype(np.int64)
        outside = (row < 0) | (row >= spec.rows) | (col < 0) | (col >= spec.cols)
        hit = outside | world.occupied[row.clip(0, spec.rows - 1), col.clip(0, spec.cols - 1)]
        np.where(hit.any(axis=1), samples_m[hit.argmax(axis=1)], np.inf)
    return (time.perf_counter() - start) / repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim-seconds", type=float, default=60.0)
    args = parser.parse_args()
    cases = [
        ("thesis exp. 4", build_world(ThesisWorld(generator="thesis", experiment=4), seed=0), 3),
        (
            "dungeon 40 m",
            build_world(
                DungeonWorld(generator="dungeon", width_m=40, height_m=40, room_count=16), seed=0
            ),
            10,
        ),
    ]
    lidar = SensorsConfig().lidar
    scans_per_sim_s = lidar.rate_hz
    for name, world, robot_count in cases:
        rtf, wall_s = real_time_factor(world, robot_count, args.sim_seconds)
        numpy_scan_s = numpy_scan_seconds(world, world.default_starts[0])
        numpy_rtf = 1.0 / (robot_count * scans_per_sim_s * numpy_scan_s)
        print(
            f"{name}: {robot_count} robots, {args.sim_seconds:g} sim s in {wall_s:.2f} wall s: "
            f"RTF {rtf:.1f}x (NumPy ray casting of the same scans alone would cap it at "
            f"{numpy_rtf:.1f}x)"
        )


if __name__ == "__main__":
    main()
