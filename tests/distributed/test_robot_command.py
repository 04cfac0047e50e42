"""``acslam run --distributed`` hands each robot process the run's faults and limits on its
command line: the command it builds must parse back to the same values."""

from __future__ import annotations

from pathlib import Path

from acslam.cli import cli
from acslam.distributed.launch import robot_command
from acslam.distributed.robot_node import RobotOptions
from acslam.transport.zenoh_link import FaultInjection


def test_a_robots_command_line_parses_back_to_the_runs_faults_and_limits() -> None:
    options = RobotOptions(
        faults=FaultInjection(0.1, 0.02), command_timeout_s=0.7, truth_out=Path("t/r.npz")
    )
    command = robot_command("thesis-exp1", 3, 5, 2, "tcp/127.0.0.1:7447", 42.0, options)
    assert command[3] == "robot"
    params = cli.commands["robot"].make_context("robot", command[4:]).params
    assert params["drop_rate"] == 0.1
    assert params["latency_ms"] == 20.0
    assert params["command_timeout_s"] == 0.7
    assert params["truth_out"] == Path("t/r.npz")
    assert (params["robot_id"], params["team"], params["seed"]) == (2, 3, 5)
    assert (params["max_time_s"], params["connect"]) == (42.0, "tcp/127.0.0.1:7447")
    assert params["scenario_name"] == "thesis-exp1"
