"""The in-process transport: two lists handed over in lock step, nothing lost or late.

``acslam run`` uses it, so the run is exactly as deterministic as the simulator.
"""

from __future__ import annotations

from collections.abc import Iterable

from acslam.messages import RobotMessage, VelocityCommand


class InProcessBus:
    """Both ends of the transport in one object (all robots share the robot end)."""

    def __init__(self) -> None:
        self._to_server: list[RobotMessage] = []
        self._to_robots: list[VelocityCommand] = []

    # robot end
    def publish(self, message: RobotMessage) -> None:
        self._to_server.append(message)

    def receive_commands(self) -> list[VelocityCommand]:
        commands, self._to_robots = self._to_robots, []
        return commands

    # server end
    def receive(self) -> list[RobotMessage]:
        messages, self._to_server = self._to_server, []
        return messages

    def send(self, commands: Iterable[VelocityCommand]) -> None:
        self._to_robots.extend(commands)
