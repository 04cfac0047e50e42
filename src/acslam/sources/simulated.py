"""The simulator as a data source: in lock step with the server, on the simulated clock."""

from __future__ import annotations

from acslam.messages import RobotMessage
from acslam.pipeline.snapshot import Snapshot
from acslam.sim.simulator import Simulator
from acslam.transport.inprocess import InProcessBus


class SimulatedSource:
    """Runs ``substeps`` simulator steps per control period; nothing is lost or late."""

    def __init__(self, sim: Simulator, substeps: int) -> None:
        self.sim = sim
        self.substeps = substeps
        self.bus = InProcessBus()

    @property
    def time_s(self) -> float:
        return self.sim.time_s

    @property
    def finished(self) -> bool:
        return False

    def newly_lost(self) -> list[int]:
        return []

    def receive(self) -> list[RobotMessage]:
        return self.bus.receive()

    def deliver(self, snapshot: Snapshot) -> None:
        self.bus.send(snapshot.commands)

    def advance(self) -> None:
        for _ in range(self.substeps):
            for message in self.sim.step(self.bus.receive_commands()):
                self.bus.publish(message)
