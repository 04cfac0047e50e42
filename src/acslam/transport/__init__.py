"""How robot messages reach the server and velocity commands reach the robots.

One interface, two implementations: :mod:`acslam.transport.inprocess` (lists handed over
in lock step: the deterministic default of ``acslam run``) and
:mod:`acslam.transport.zenoh_link` (Eclipse Zenoh between processes or hosts). The
server side and the robot side see only these two protocols.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable
from typing import Protocol

from acslam.messages import RobotMessage, VelocityCommand

STATUS_KEY = "acslam/server/status"


def robot_key(robot_id: int, topic: str) -> str:
    """The Zenoh key expression of one robot topic, e.g. ``acslam/robot_0/odom``."""
    return f"acslam/robot_{robot_id}/{topic}"


class RobotEndpoint(Protocol):
    """A robot's end: sends its sensor messages, gets the commands addressed to it."""

    def publish(self, message: RobotMessage) -> None: ...

    def receive_commands(self) -> list[VelocityCommand]: ...


class ServerEndpoint(Protocol):
    """The server's end: gets every robot's messages, sends their commands."""

    def receive(self) -> list[RobotMessage]: ...

    def send(self, commands: Iterable[VelocityCommand]) -> None: ...


class CommandInbox:
    """The velocity commands a robot's link receives on a network thread, kept until the
    robot's loop takes them; and when the last one came."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._commands: list[VelocityCommand] = []
        self._last_s: float | None = None

    def put(self, command: VelocityCommand) -> None:
        with self._lock:
            self._commands.append(command)
            self._last_s = time.monotonic()

    def take(self) -> list[VelocityCommand]:
        """The commands since the last call, oldest first."""
        with self._lock:
            commands, self._commands = self._commands, []
        return commands

    @property
    def last_s(self) -> float | None:
        """Monotonic time the last command arrived (None before the first)."""
        with self._lock:
            return self._last_s
