"""``acslam robot``: one simulated robot in real time, talking to the server over Zenoh.

The robot runs the scenario's full :class:`~acslam.sim.simulator.Simulator` (so its
noise streams are exactly those of robot ``id`` in-process) but drives only itself: the
other robots are placed each step at the true pose they last published on the
ground-truth side channel (``acslam/robot_<j>/truth``), so this robot's LiDAR sees them
and its motion collides with them. That channel exists for the simulation and the
evaluation only; the server never reads it. The other robots' own sensor output in this
process is discarded.

Behaviour under faults: without a command for ``command_timeout_s`` the robot stops
(zero velocity) and resumes as commands come back (server restart); without any server
status for ``server_timeout_s`` (``startup_timeout_s`` before the first) it gives up.
Heartbeats go out every ``heartbeat_period_s`` carrying the robot's dead-reckoned pose.
Injected loss and latency (:class:`~acslam.transport.zenoh_link.FaultInjection`) hit its
sensor messages only.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from acslam import stop
from acslam.errors import TransportError
from acslam.files import atomic_path
from acslam.messages import RobotMessage, VelocityCommand
from acslam.scenario import Scenario
from acslam.sim.simulator import Simulator
from acslam.transport.codec import StatusBeacon, TruthBatch
from acslam.transport.zenoh_link import FaultInjection, ZenohRobotEndpoint, open_session

_FAULT_STREAM = 100  # spawn key of the fault-injection stream, apart from acslam.seeding's


@dataclass(frozen=True)
class RobotOptions:
    """Timing, faults and outputs of one robot node (wall-clock seconds)."""

    faults: FaultInjection = field(default_factory=FaultInjection)
    command_timeout_s: float = 0.5
    heartbeat_period_s: float = 0.2
    server_timeout_s: float = 30.0
    startup_timeout_s: float = 120.0
    truth_out: Path | None = None


class RobotLink(Protocol):
    """A robot's end of the network, as the agent uses it (the acslam protocol's
    :class:`~acslam.transport.zenoh_link.ZenohRobotEndpoint`, or ROS 2 topics)."""

    def publish(self, message: RobotMessage) -> None: ...

    def flush(self) -> None: ...

    def heartbeat(self, stamp: float) -> None: ...

    def publish_truth(self, batch: TruthBatch) -> None: ...

    def receive_commands(self) -> list[VelocityCommand]: ...

    def status(self) -> tuple[float, StatusBeacon] | None: ...

    def other_poses(self) -> dict[int, np.ndarray]: ...

    def stats_summary(self) -> dict: ...


def run_robot(
    scenario: Scenario, robot_id: int, connect: str, max_time_s: float, options: RobotOptions
) -> str:
    """Drive robot ``robot_id`` until the server says the run is over; returns why it
    stopped."""
    if not 0 <= robot_id < scenario.robot_count:
        raise TransportError(
            f"--id: robot {robot_id} does not exist, the team has {scenario.robot_count}"
        )
    config = scenario.config
    sim = scenario.simulator()
    fault_rng = np.random.default_rng(
        np.random.SeedSequence(entropy=config.seed, spawn_key=(_FAULT_STREAM, robot_id))
    )
    session = open_session(connect=[connect])
    try:
        link = ZenohRobotEndpoint(
            session, robot_id, scenario.starts[robot_id], options.faults, fault_rng
        )
        period_s = config.algorithms.planning.control_period_s
        agent = RobotAgent(sim, link, robot_id, options, config.sim.dt_s, period_s)
        return agent.run(max_time_s)
    finally:
        session.close()


class RobotAgent:
    """The real-time loop of one robot node; a stopping signal (:mod:`acslam.stop`) ends
    it with that reason (``terminated``, ``interrupted``), its ground-truth log written."""

    def __init__(
        self,
        sim: Simulator,
        link: RobotLink,
        robot_id: int,
        options: RobotOptions,
        dt_s: float,
        truth_period_s: float,
    ) -> None:
        self.sim = sim
        self.dt_s = dt_s
        self.link = link
        self.robot_id = robot_id
        self.options = options
        self.truth_period_s = truth_period_s
        start = sim.ground_truth.poses()[robot_id]
        self.truth_rows: list[tuple[float, float, float, float]] = [(0.0, *start)]
        self.sent_rows = 0
        self.stops = 0

    def run(self, max_time_s: float, *, wait_for_server: bool = True) -> str:
        """Drive until the server says the run is over, goes silent, :attr:`stop` is set
        or ``max_time_s``; without ``wait_for_server`` (a ROS 2 robot) it starts at once,
        standing still until commands come."""
        options, link = self.options, self.link
        if wait_for_server and not self._wait_for_server():
            return self._finish("no server")
        dt_s = self.dt_s
        command = VelocityCommand(self.robot_id, 0.0, 0.0, 0.0)
        stopped = False
        started = last_command = last_status = next_beat = next_truth = time.monotonic()
        reason = "time limit"
        while self.sim.time_s < max_time_s:
            stopped = stop.requested()
            if stopped is not None:
                reason = stopped
                break
            time.sleep(max(0.0, started + self.sim.time_s + dt_s - time.monotonic()))
            now = time.monotonic()
            received = link.receive_commands()
            if received:
                command, last_command, stopped = received[-1], now, False
            elif not stopped and now - last_command > options.command_timeout_s:
                command, stopped = VelocityCommand(self.robot_id, 0.0, 0.0, 0.0), True
                self.stops += 1
            status = link.status()
            if status is not None:
                last_status = status[0]
                if status[1].finished:
                    reason = "run over"
                    break
            if now - last_status > options.server_timeout_s:
                reason = "server lost"
                break
            self._step(command)
            if now >= next_beat:
                link.heartbeat(self.sim.time_s)
                next_beat += options.heartbeat_period_s
            if now >= next_truth:
                self._publish_truth()
                next_truth += self.truth_period_s
        self._publish_truth()
        return self._finish(reason)

    def _wait_for_server(self) -> bool:
        """Heartbeat (at the start pose, clock at 0) until the server's status arrives."""
        deadline = time.monotonic() + self.options.startup_timeout_s
        while self.link.status() is None:
            if time.monotonic() > deadline:
                return False
            self.link.heartbeat(0.0)
            time.sleep(self.options.heartbeat_period_s)
        return True

    def _step(self, command: VelocityCommand) -> None:
        for other, pose in self.link.other_poses().items():
            self.sim.place_robot(other, pose)  # the others' poses come from the truth channel
        for message in self.sim.step([command]):
            if message.robot_id == self.robot_id:
                self.link.publish(message)
        self.link.flush()
        pose = self.sim.ground_truth.poses()[self.robot_id]
        self.truth_rows.append((self.sim.time_s, *pose))

    def _publish_truth(self) -> None:
        rows = np.array(self.truth_rows[self.sent_rows :]).reshape(-1, 4)
        if len(rows):
            collisions = self.sim.ground_truth.collisions[self.robot_id]
            self.link.publish_truth(TruthBatch(self.robot_id, rows[:, 0], rows[:, 1:], collisions))
            self.sent_rows = len(self.truth_rows)

    def _finish(self, reason: str) -> str:
        """Write the local ground-truth log (atomically) and say why the robot stopped."""
        path = self.options.truth_out
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_path(path) as temporary:
                np.savez(
                    temporary,
                    trajectory=np.array(self.truth_rows),
                    collisions=self.sim.ground_truth.collisions[self.robot_id],
                    link=json.dumps(
                        {"reason": reason, "stops": self.stops, **self.link.stats_summary()}
                    ),
                )
        return reason
