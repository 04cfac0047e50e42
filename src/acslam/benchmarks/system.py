"""Whole-system benchmarks: the server cycle in a real run, iSAM2 growth, simulator speed."""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from acslam.benchmarks.core import Figure
from acslam.benchmarks.isam2 import measure_isam2_updates
from acslam.benchmarks.loop_closure import measure_loop_candidate_search
from acslam.config import (
    DungeonWorld,
    LandmarkConfig,
    RobotsConfig,
    SensorsConfig,
    SimConfig,
    ThesisWorld,
)
from acslam.messages import VelocityCommand
from acslam.runner import run_exploration
from acslam.scenario import load_scenario
from acslam.seeding import Stream, rng
from acslam.sim.lidar import beam_angles
from acslam.sim.simulator import Simulator
from acslam.worlds.generators import build_world
from acslam.worlds.landmarks import place_landmarks
from acslam.worlds.world import World

DEFAULT_SCENARIO = "thesis-exp1"


def bench_server_cycle(quick: bool) -> list[Figure]:
    """Server time per module in the first seconds of the default run, per control period."""
    scenario = load_scenario(DEFAULT_SCENARIO)
    period_ms = 1e3 * scenario.config.algorithms.planning.control_period_s
    with tempfile.TemporaryDirectory() as folder:
        metrics = run_exploration(scenario, Path(folder), max_time_s=10.0 if quick else 40.0)
    cycle = metrics["server_cycle_ms"]
    reference = f"control period ({period_ms:g} ms)"
    label = f"{DEFAULT_SCENARIO}, {scenario.robot_count} robots, {metrics['sim_time_s']:.0f} s"
    figures = [
        Figure(
            "server",
            f"server cycle, whole ({label})",
            cycle["mean"],
            "ms",
            reference,
            period_ms,
            f"p95 {cycle['p95']:.1f} ms",
        ),
    ]
    for module, value in cycle.items():
        if isinstance(value, dict):
            figures.append(
                Figure(
                    "server",
                    f"server cycle: {module}",
                    value["mean"],
                    "ms",
                    reference,
                    period_ms,
                    f"p95 {value['p95']:.1f} ms",
                )
            )
    return figures


def bench_isam2(quick: bool) -> list[Figure]:
    """iSAM2 update time per 500 keyframes of graph size (:mod:`acslam.benchmarks.isam2`),
    and the loop-closure candidate search per 1000 (:mod:`acslam.benchmarks.loop_closure`).

    Three robots circle through a landmark grid, closing loops every lap; the reference
    is the mean update over the first 500 keyframes. Three robots lap a corridor; the
    reference is the search over all keyframes it replaced, on the same state.
    """
    result = measure_isam2_updates(1000 if quick else 3000, robots=3, seed=0)
    buckets = result["buckets"]
    base_ms = buckets[0]["mean_ms"]
    figures = [
        Figure(
            "slam",
            f"iSAM2 update, keyframes {b['from']}-{b['to']} (3 robots)",
            b["mean_ms"],
            "ms",
            f"iSAM2 update, keyframes {buckets[0]['from']}-{buckets[0]['to']}",
            base_ms,
            f"p95 {b['p95_ms']:.1f} ms, {b['per_keyframe_p95_ms']:.1f} ms per keyframe; "
            f"association p95 {b['association_p95_ms']:.1f} ms per frame",
        )
        for b in buckets
    ]
    search = measure_loop_candidate_search(1000 if quick else 3000, robots=3, seed=0)
    figures += [
        Figure(
            "slam",
            f"loop-closure candidates, keyframes {b['from']}-{b['to']} (3 robots)",
            b["index_mean_ms"],
            "ms",
            "search over all keyframes",
            b["exhaustive_mean_ms"],
            f"p95 {b['index_p95_ms']:.1f} ms",
        )
        for b in search["buckets"]
        if b["exhaustive_mean_ms"]
    ]
    return figures


def _scripted(time_s: float, robot_count: int, v_mps: float) -> list[VelocityCommand]:
    return [
        VelocityCommand(i, time_s, v_mps, 1.5 * math.sin(0.4 * time_s + 1.3 * i))
        for i in range(robot_count)
    ]


def _real_time_factor(world: World, robot_count: int, sim_seconds: float) -> float:
    """Simulated over wall seconds with every sensor at its rate and no server."""
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
    for _ in range(round(1.0 / SimConfig().dt_s)):  # JIT compile / cache load
        sim.step(_scripted(sim.time_s, robot_count, robots.max_v_mps))
    start = time.perf_counter()
    for _ in range(round(sim_seconds / SimConfig().dt_s)):
        sim.step(_scripted(sim.time_s, robot_count, robots.max_v_mps))
    return sim_seconds / (time.perf_counter() - start)


def _numpy_scan_s(world: World, pose: np.ndarray, repeats: int = 10) -> float:
    """Wall time of one default scan sampled every quarter cell in plain NumPy."""
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


def bench_simulator(quick: bool) -> list[Figure]:
    """Simulator real-time factor against the cap plain-NumPy ray casting would impose."""
    sim_seconds = 10.0 if quick else 60.0
    cases = [
        ("thesis exp. 4", build_world(ThesisWorld(generator="thesis", experiment=4), seed=0), 3),
        (
            "dungeon 40 m",
            build_world(
                DungeonWorld(generator="dungeon", width_m=40, height_m=40, room_count=16), seed=0
            ),
            8,
        ),
    ]
    figures = []
    for name, world, robot_count in cases:
        rtf = _real_time_factor(world, robot_count, sim_seconds)
        scans_per_s = robot_count * SensorsConfig().lidar.rate_hz
        numpy_cap = 1.0 / (scans_per_s * _numpy_scan_s(world, world.default_starts[0]))
        figures.append(
            Figure(
                "simulator",
                f"real-time factor, {name}, {robot_count} robots",
                rtf,
                "x",
                "NumPy ray-casting cap (scans alone)",
                numpy_cap,
                "higher is faster; ratio > 1: faster than NumPy could cast the scans",
            )
        )
    return figures
