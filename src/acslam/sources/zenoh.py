"""Robots over Zenoh as a data source, on the wall clock since the source was made."""

from __future__ import annotations

import time

from acslam.messages import RobotMessage
from acslam.pipeline.snapshot import Snapshot
from acslam.sources import LiveSource
from acslam.transport.codec import StatusBeacon
from acslam.transport.zenoh_link import ZenohServerEndpoint


class ZenohSource(LiveSource):
    """Messages as they arrive; a robot whose heartbeats stop for ``heartbeat_timeout_s``
    is reported lost once and ignored from then on."""

    def __init__(
        self, endpoint: ZenohServerEndpoint, period_s: float, heartbeat_timeout_s: float
    ) -> None:
        super().__init__(period_s)
        self.endpoint = endpoint
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self._lost: set[int] = set()

    def newly_lost(self) -> list[int]:
        wall = time.monotonic()
        silent = [
            robot
            for robot, (heard_s, _) in self.endpoint.heartbeats().items()
            if robot not in self._lost and wall - heard_s > self.heartbeat_timeout_s
        ]
        for robot in silent:
            self._lost.add(robot)
            self.endpoint.ignore(robot)
        return silent

    def receive(self) -> list[RobotMessage]:
        return self.endpoint.receive()

    def deliver(self, snapshot: Snapshot) -> None:
        self.endpoint.send(snapshot.commands)
        status = StatusBeacon(snapshot.time_s, snapshot.finished, tuple(snapshot.lost))
        self.endpoint.publish_status(status)
