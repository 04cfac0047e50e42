"""How robot messages reach the server and velocity commands reach the robots.

One interface, two implementations: :mod:`acslam.transport.inprocess` (lists handed over
in lock step: the deterministic default of ``acslam run``) and
:mod:`acslam.transport.zenoh_link` (Eclipse Zenoh between processes or hosts). The
server side and the robot side see only these two protocols.
"""

from __future__ import annotations

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
