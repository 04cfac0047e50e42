"""Runs a scenario on the simulated clock and writes the run folder.

The robots are driven by :class:`ScanWanderer`, a controller that reads nothing but each
robot's own LiDAR scans, so a run exercises exactly the robot -> server contract.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import yaml

from acslam.eval.figures import plot_world
from acslam.geometry import compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, VelocityCommand
from acslam.scenario import Scenario
from acslam.sim.simulator import Simulator
from acslam.trajectory import write_tum
from acslam.worlds.mapio import save_map, world_cells


class ScanWanderer:
    """Scan-reactive wandering: cruise, steer toward open space, turn away from obstacles.

    Each robot's command depends only on its own scans: forward speed scales with the
    free distance in a sector ahead, steering leans toward the side whose beams reach
    further, and a blocked robot turns in place, keeping its turn direction until the
    way ahead is clear again (so it cannot dither between two walls).
    """

    def __init__(
        self, robot_count: int, max_v_mps: float, max_omega_radps: float, clearance_m: float = 0.5
    ) -> None:
        self.max_v_mps = max_v_mps
        self.max_omega_radps = max_omega_radps
        self.clearance_m = clearance_m
        self._commands = {i: (0.0, 0.0) for i in range(robot_count)}
        self._turning: dict[int, float] = {}

    def observe(self, scan: LidarScan) -> None:
        ranges = np.minimum(scan.ranges, scan.range_max_m)
        ahead = np.abs(scan.angles) < math.radians(40)
        left = (scan.angles > math.radians(20)) & (scan.angles < math.radians(100))
        right = (scan.angles < -math.radians(20)) & (scan.angles > -math.radians(100))
        # Distance ahead along the heading, for beams whose lateral offset hits the body.
        lateral = np.abs(ranges * np.sin(scan.angles))
        body = ahead & (lateral < self.clearance_m)
        free_ahead = float((ranges * np.cos(scan.angles))[body].min(initial=scan.range_max_m))
        balance = (ranges[left].mean() - ranges[right].mean()) / scan.range_max_m
        robot = scan.robot_id
        if robot in self._turning:
            if free_ahead > 2.0 * self.clearance_m:
                del self._turning[robot]
        elif free_ahead < self.clearance_m:
            self._turning[robot] = 1.0 if balance >= 0 else -1.0
        if robot in self._turning:
            v, omega = 0.0, self._turning[robot] * 0.6 * self.max_omega_radps
        else:
            v = self.max_v_mps * min(1.0, (free_ahead - self.clearance_m) / self.clearance_m)
            omega = float(np.clip(1.5 * balance, -1.0, 1.0)) * 0.3 * self.max_omega_radps
        self._commands[robot] = (v, omega)

    def commands(self, stamp: float) -> list[VelocityCommand]:
        return [VelocityCommand(i, stamp, v, w) for i, (v, w) in self._commands.items()]


@dataclass
class RobotSummary:
    name: str
    distance_m: float
    odometry_drift_m: float
    wall_collisions: int
    robot_collisions: int
    scans: int
    landmark_observations: int


@dataclass
class RunSummary:
    scenario: str
    sim_time_s: float
    wall_time_s: float
    robots: list[RobotSummary]

    @property
    def real_time_factor(self) -> float:
        return self.sim_time_s / max(self.wall_time_s, 1e-9)


def run_simulation(
    scenario: Scenario,
    duration_s: float,
    out_dir: Path,
    on_progress: Callable[[float], None] | None = None,
) -> RunSummary:
    """Simulate ``duration_s`` seconds and write the run folder ``out_dir``.

    The folder holds ``config.yaml`` (the resolved scenario), ``map.yaml``/``map.pgm``/
    ``map.png`` (ground truth), ``trajectories/robot_<i>.{groundtruth,odometry}.tum``
    and ``summary.json``.
    """
    config = scenario.config
    sim = Simulator(
        scenario.world,
        scenario.starts,
        scenario.landmarks,
        config.robots,
        config.sensors,
        config.sim,
        config.seed,
    )
    count = scenario.robot_count
    wanderer = ScanWanderer(count, config.robots.max_v_mps, config.robots.max_omega_radps)
    odometry_poses = {i: [scenario.starts[i].copy()] for i in range(count)}
    odometry_stamps = {i: [0.0] for i in range(count)}
    scans = dict.fromkeys(range(count), 0)
    observations = dict.fromkeys(range(count), 0)

    steps = round(duration_s / config.sim.dt_s)
    report_every = max(1, steps // 200)
    started = time.perf_counter()
    commands = wanderer.commands(0.0)
    for step in range(steps):
        for message in sim.step(commands):
            robot = message.robot_id
            if isinstance(message, LidarScan):
                wanderer.observe(message)
                scans[robot] += 1
            elif isinstance(message, OdometryIncrement):
                odometry_poses[robot].append(compose(odometry_poses[robot][-1], message.delta))
                odometry_stamps[robot].append(message.stamp)
            elif isinstance(message, LandmarkObservations):
                observations[robot] += len(message.points)
        commands = wanderer.commands(sim.time_s)
        if on_progress is not None and (step % report_every == 0 or step == steps - 1):
            on_progress(sim.time_s)
    wall_time_s = time.perf_counter() - started

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    resolved = config.model_dump(mode="json")
    resolved["robots"]["count"] = count
    resolved["robots"]["starts"] = scenario.starts.tolist()
    (out_dir / "config.yaml").write_text(yaml.safe_dump(resolved, sort_keys=False))
    save_map(out_dir / "map", world_cells(scenario.world), scenario.world.spec)

    truth = sim.ground_truth
    robots: list[RobotSummary] = []
    trajectories = []
    for i in range(count):
        true_track = truth.trajectory(i)
        trajectories.append(true_track[:, 1:])
        odom = np.array(odometry_poses[i])
        write_tum(
            out_dir / "trajectories" / f"robot_{i}.groundtruth.tum",
            true_track[:, 0],
            true_track[:, 1:],
        )
        write_tum(
            out_dir / "trajectories" / f"robot_{i}.odometry.tum", np.array(odometry_stamps[i]), odom
        )
        steps_xy = np.diff(true_track[:, 1:3], axis=0)
        final_truth = truth.poses()[i]
        robots.append(
            RobotSummary(
                name=f"robot_{i}",
                distance_m=float(np.hypot(steps_xy[:, 0], steps_xy[:, 1]).sum()),
                odometry_drift_m=float(np.hypot(*(odom[-1, :2] - final_truth[:2]))),
                wall_collisions=int(truth.collisions[i, 0]),
                robot_collisions=int(truth.collisions[i, 1]),
                scans=scans[i],
                landmark_observations=observations[i],
            )
        )
    plot_world(
        scenario.world, scenario.starts, scenario.landmarks, out_dir / "map.png", trajectories
    )
    summary = RunSummary(config.name, sim.time_s, wall_time_s, robots)
    (out_dir / "summary.json").write_text(
        json.dumps(asdict(summary) | {"real_time_factor": summary.real_time_factor}, indent=2)
    )
    return summary
