"""``acslam run --distributed``: the server here, one ``acslam robot`` process per robot,
all on loopback, writing the same run folder as an in-process run.

Robot logs go to ``DIR/logs/robot_<i>.log``, their local ground-truth logs to
``DIR/truth/robot_<i>.npz``.
"""

from __future__ import annotations

import socket
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

from acslam.distributed.robot_node import RobotOptions
from acslam.distributed.server_node import serve
from acslam.runner import NO_HOOKS, RunHooks
from acslam.scenario import Scenario

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
    hooks: RunHooks = NO_HOOKS,
) -> dict:
    """Start N robot processes, serve them until the run ends, collect; returns metrics."""
    robot_options = robot_options or RobotOptions()
    out_dir = Path(out_dir)
    (out_dir / "logs").mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    processes = []
    try:
        for i in range(scenario.robot_count):
            options = replace(robot_options, truth_out=out_dir / "truth" / f"robot_{i}.npz")
            command = robot_command(
                scenario_arg,
                scenario.robot_count,
                scenario.config.seed,
                i,
                endpoint,
                max_time_s + 30.0,
                options,
            )
            with (out_dir / "logs" / f"robot_{i}.log").open("w") as log:
                processes.append(subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT))
        return serve(scenario, endpoint, out_dir, max_time_s, hooks=hooks)
    except BaseException:  # the server failed or was interrupted: the robots go with it
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
