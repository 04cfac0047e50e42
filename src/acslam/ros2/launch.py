"""``acslam run --distributed --ros2`` (:func:`acslam.distributed.launch.run_distributed`
with ``ros2``): the server here and one simulated ROS 2 robot process per robot (``acslam
robot --ros2``), on loopback, in real time.

The server's session is the Zenoh router the robots connect to, as ``rmw_zenohd`` is
for a real team. When the run ends the robots are stopped (SIGTERM) and each writes its
ground-truth log, from which the run is scored, as in every other run.
"""

from __future__ import annotations

import json
import signal
import sys
from pathlib import Path

import numpy as np

from acslam.distributed.launch import robot_processes, truth_path
from acslam.ros2.node import Ros2Options
from acslam.ros2.serve import Ros2ServeOptions, serve_ros2
from acslam.ros2.source import Ros2Source
from acslam.runner import RunHooks, TruthLog
from acslam.scenario import Scenario

EXTRA_ROBOT_TIME_S = 30.0
"""Robots may run this much longer than the server's limit: the server ends the run."""


def default_namespaces(count: int) -> list[str]:
    """``robot_0``, ``robot_1``, ...: the namespaces of a simulated team."""
    return [f"robot_{i}" for i in range(count)]


def robot_command(
    scenario_arg: str,
    scenario: Scenario,
    robot_id: int,
    namespaces: list[str],
    connect: str,
    max_time_s: float,
    ros2: Ros2Options,
    truth_out: Path,
) -> list[str]:
    """The command line of one simulated ROS 2 robot."""
    return [
        sys.executable, "-m", "acslam.cli", "robot", "--ros2",
        "--id", str(robot_id),
        "--robots", ",".join(namespaces),
        "--connect", connect,
        "--scenario", scenario_arg,
        "--seed", str(scenario.config.seed),
        "--max-time", str(max_time_s),
        "--distro", ros2.distro,
        "--attachment", ros2.attachment,
        "--domain-id", str(ros2.domain_id),
        "--truth-out", str(truth_out),
    ]  # fmt: skip


def serve_simulated_team(
    scenario: Scenario,
    scenario_arg: str,
    out_dir: Path,
    max_time_s: float,
    endpoint: str,
    ros2: Ros2Options,
    hooks: RunHooks,
) -> dict:
    """Start the robot processes (connecting to ``endpoint``, where the server is the
    router), serve them over ROS 2 until the run ends, score it from their ground-truth
    logs; returns the metrics."""
    namespaces = default_namespaces(scenario.robot_count)
    commands = [
        robot_command(
            scenario_arg, scenario, i, namespaces, endpoint,
            max_time_s + EXTRA_ROBOT_TIME_S, ros2, truth_path(out_dir, i),
        )
        for i in range(scenario.robot_count)
    ]  # fmt: skip
    options = Ros2ServeOptions(tuple(namespaces), ros2, listen=endpoint)
    with robot_processes(commands, out_dir) as processes:

        def truth(source: Ros2Source) -> TruthLog:
            for process in processes:
                process.send_signal(signal.SIGTERM)
            for process in processes:
                process.wait()
            return robot_truth(out_dir, scenario, source.clock_origin_s)

        return serve_ros2(scenario, out_dir, max_time_s, options, truth=truth, hooks=hooks)


def robot_truth(out_dir: Path, scenario: Scenario, clock_origin_s: float) -> TruthLog:
    """The robots' ground-truth logs on the server's clock (each robot stamps on its own,
    from its ``clock_origin_s``); a robot without a log stays at its start."""
    trajectories, collisions = [], np.zeros((scenario.robot_count, 2), dtype=np.int64)
    for i in range(scenario.robot_count):
        path = truth_path(out_dir, i)
        if not path.is_file():
            trajectories.append(np.array([[0.0, *scenario.starts[i]]]))
            continue
        with np.load(path) as log:
            rows = np.array(log["trajectory"], dtype=float)
            collisions[i] = log["collisions"]
            origin_s = json.loads(str(log["link"]))["clock_origin_s"]
        rows[:, 0] += origin_s - clock_origin_s
        trajectories.append(rows)
    return TruthLog(trajectories, collisions)
