"""``acslam run --distributed``: the server here, one ``acslam robot`` process per robot,
all on loopback, writing the same run folder as an in-process run.

Robot logs go to ``DIR/logs/robot_<i>.log``, their local ground-truth logs to
``DIR/truth/robot_<i>.npz``.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from acslam.distributed.robot_node import RobotOptions
from acslam.distributed.server_node import serve
from acslam.runner import NO_HOOKS, RunHooks
from acslam.scenario import Scenario

if TYPE_CHECKING:
    from acslam.ros2.node import Ros2Options

ROBOT_EXIT_TIMEOUT_S = 15.0


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def robot_command(
    scenario_arg: str,
    robots: int,
    seed: int,
    robot_id: int,
    connect: str,
    max_time_s: float,
    options: RobotOptions,
) -> list[str]:
    """The command line of one robot node."""
    command = [
        sys.executable,
        "-m",
        "acslam.cli",
        "robot",
        "--id",
        str(robot_id),
        "--connect",
        connect,
        "--scenario",
        scenario_arg,
        "--robots",
        str(robots),
        "--seed",
        str(seed),
        "--max-time",
        str(max_time_s),
        "--drop-rate",
        str(options.faults.drop_rate),
        "--latency-ms",
        str(1000 * options.faults.latency_s),
        "--command-timeout",
        str(options.command_timeout_s),
    ]
    if options.truth_out is not None:
        command += ["--truth-out", str(options.truth_out)]
    return command


def run_distributed(
    scenario: Scenario,
    scenario_arg: str,
    out_dir: Path,
    max_time_s: float,
    *,
    robot_options: RobotOptions | None = None,
    ros2: Ros2Options | None = None,
    hooks: RunHooks = NO_HOOKS,
) -> dict:
    """Start N robot processes, serve them until the run ends, collect; returns metrics.
    With ``ros2`` the robots and the server speak ROS 2 (:mod:`acslam.ros2.launch`)."""
    out_dir = Path(out_dir)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    if ros2 is not None:
        from acslam.ros2.launch import serve_simulated_team

        return serve_simulated_team(
            scenario, scenario_arg, out_dir, max_time_s, endpoint, ros2, hooks
        )
    robot_options = robot_options or RobotOptions()
    commands = [
        robot_command(
            scenario_arg,
            scenario.robot_count,
            scenario.config.seed,
            i,
            endpoint,
            max_time_s + 30.0,
            replace(robot_options, truth_out=truth_path(out_dir, i)),
        )
        for i in range(scenario.robot_count)
    ]
    with robot_processes(commands, out_dir):
        return serve(scenario, endpoint, out_dir, max_time_s, hooks=hooks)


def truth_path(out_dir: Path, robot_id: int) -> Path:
    """Where robot node ``robot_id`` writes its ground-truth log."""
    return Path(out_dir) / "truth" / f"robot_{robot_id}.npz"


@contextmanager
def robot_processes(commands: list[list[str]], out_dir: Path) -> Iterator[list[subprocess.Popen]]:
    """One process per robot command, output to ``out_dir/logs/robot_<i>.log``. If the
    server fails or is interrupted the robots are killed; otherwise they get
    ``ROBOT_EXIT_TIMEOUT_S`` to end on their own."""
    (Path(out_dir) / "logs").mkdir(parents=True, exist_ok=True)
    processes = []
    try:
        for i, command in enumerate(commands):
            with (Path(out_dir) / "logs" / f"robot_{i}.log").open("w") as log:
                processes.append(subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT))
        yield processes
    except BaseException:
        for process in processes:
            process.kill()
        raise
    finally:
        for process in processes:
            try:
                process.wait(timeout=ROBOT_EXIT_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
