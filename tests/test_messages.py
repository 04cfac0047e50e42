"""The robot <-> server messages reject invalid values where they are built."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from acslam.errors import MessageError
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, VelocityCommand


def test_valid_messages_build() -> None:
    scan = LidarScan(0, 1.0, np.zeros(3), np.array([1.0, math.inf, 0.5]), 8.0)
    assert scan.ranges.dtype == float
    assert LandmarkObservations(1, 2.0, np.empty((0, 3))).points.shape == (0, 3)
    assert OdometryIncrement(2, 1.0, 0.5, 0.1, 0.0, 0.01).delta.tolist() == [0.1, 0.0, 0.01]


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: VelocityCommand(0, 0.0, math.nan, 0.0), "VelocityCommand.v"),
        (lambda: VelocityCommand(0, 0.0, 0.1, math.inf), "VelocityCommand.omega"),
        (lambda: VelocityCommand(-1, 0.0, 0.1, 0.0), "VelocityCommand.robot_id"),
        (lambda: OdometryIncrement(0, math.nan, 0.0, 0.0, 0.0, 0.0), "OdometryIncrement.stamp"),
        (lambda: OdometryIncrement(0, 1.0, 0.0, math.nan, 0.0, 0.0), "OdometryIncrement.dx"),
        (lambda: OdometryIncrement(0, 1.0, 2.0, 0.0, 0.0, 0.0), "OdometryIncrement.start_stamp"),
        (lambda: LidarScan(0, 0.0, np.zeros(2), np.array([1.0, math.nan]), 8.0), "ranges"),
        (lambda: LidarScan(0, 0.0, np.zeros(2), np.array([1.0, -0.1]), 8.0), "ranges"),
        (lambda: LidarScan(0, 0.0, np.zeros(3), np.ones(2), 8.0), "ranges"),
        (lambda: LidarScan(0, 0.0, np.array([0.0, math.nan]), np.ones(2), 8.0), "angles"),
        (lambda: LandmarkObservations(0, 0.0, np.array([[0.0, math.inf, 1.0]])), "points"),
        (lambda: LandmarkObservations(0, 0.0, np.ones((2, 2))), "points"),
        (
            lambda: LandmarkObservations(0, 0.0, np.ones((2, 3)), np.zeros((3, 32), np.uint8)),
            "descriptors",
        ),
    ],
)
def test_invalid_message_is_rejected_naming_the_field(build, field: str) -> None:
    with pytest.raises(MessageError, match=field.replace(".", r"\.")):
        build()


def test_messages_are_immutable() -> None:
    command = VelocityCommand(0, 0.0, 0.1, 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        command.v = 1.0  # type: ignore[misc]
