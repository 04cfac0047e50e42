"""The Zenoh endpoints in one process: bad payloads are dropped and counted, lost
odometry increments are bridged, injected loss follows its seeded rate."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import msgpack
import numpy as np
import pytest

from acslam.distributed.launch import free_port
from acslam.errors import TransportError
from acslam.geometry import compose
from acslam.messages import LidarScan, OdometryIncrement
from acslam.transport import robot_key
from acslam.transport.codec import encode
from acslam.transport.zenoh_link import (
    FaultInjection,
    ZenohRobotEndpoint,
    ZenohServerEndpoint,
    open_session,
)


@pytest.fixture
def link() -> Iterator[tuple]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    server_session = open_session(listen=endpoint)
    robot_session = open_session(connect=[endpoint])
    server = ZenohServerEndpoint(server_session, robot_count=2)
    time.sleep(0.5)  # let the sessions connect and the subscriptions propagate
    yield server, robot_session
    robot_session.close()
    server_session.close()


def _until(condition, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)


def _scan(robot_id: int) -> LidarScan:
    return LidarScan(robot_id, 1.0, np.array([0.0, 1.0]), np.array([2.0, np.inf]), 8.0)


def test_bad_payloads_are_dropped_and_counted(link: tuple) -> None:
    server, session = link
    scan_key = robot_key(0, "scan")
    nan_scan = msgpack.unpackb(encode(_scan(0)))
    nan_scan["g"][2] = np.array([np.nan, 1.0]).tobytes()
    session.put(scan_key, b"\x00garbage")
    session.put(scan_key, msgpack.packb(nan_scan))
    session.put(scan_key, encode(_scan(1)))  # robot 1's scan on robot 0's key
    session.put(robot_key(7, "scan"), encode(_scan(7)))  # no such robot
    session.put(scan_key, encode(_scan(0)))
    _until(lambda: sum(server.stats.dropped.values()) == 4 and server.stats.messages)
    received = server.receive()
    assert [(m.robot_id, type(m).__name__) for m in received] == [(0, "LidarScan")]
    assert sum(server.stats.dropped.values()) == 4
    assert server.stats.dropped["scan: CodecError"] == 3
    assert server.stats.dropped["scan: MessageError"] == 1  # the NaN range


def test_lost_odometry_is_bridged_from_the_cumulative_pose(link: tuple) -> None:
    server, session = link
    robot = ZenohRobotEndpoint(
        session, 1, np.array([1.0, 2.0, 0.5]), FaultInjection(), np.random.default_rng(0)
    )
    steps = [OdometryIncrement(1, 0.1 * (k + 1), 0.1 * k, 0.05, 0.01, 0.1) for k in range(3)]
    robot.publish(steps[0])
    robot.faults = FaultInjection(drop_rate=0.999999)  # the second increment is lost
    robot.publish(steps[1])
    robot.faults = FaultInjection()
    robot.publish(steps[2])
    _until(lambda: server.stats.messages[(1, "odom")] == 2)
    first, second = server.receive()
    assert (second.start_stamp, second.stamp) == (first.stamp, steps[2].stamp)
    np.testing.assert_allclose(second.delta, compose(steps[1].delta, steps[2].delta), atol=1e-12)
    assert server.stats.dropped["odom: gap bridged"] == 1
    expected = np.array([1.0, 2.0, 0.5])
    for step in steps:
        expected = compose(expected, step.delta)
    np.testing.assert_allclose(robot.pose, expected)


def test_injected_loss_follows_the_seeded_rate(link: tuple) -> None:
    _, session = link
    robot = ZenohRobotEndpoint(
        session, 0, np.zeros(3), FaultInjection(drop_rate=0.1), np.random.default_rng(5)
    )
    for k in range(2000):
        robot.publish(LidarScan(0, float(k), np.zeros(1), np.ones(1), 8.0))
    dropped = robot.stats.dropped["scan: injected"]
    assert dropped + robot.stats.messages[(0, "scan")] == 2000
    assert math.isclose(dropped / 2000, 0.1, abs_tol=0.02)


def test_bad_endpoint_and_fault_settings_are_one_clear_error() -> None:
    with pytest.raises(TransportError, match="--listen: expected tcp/HOST:PORT"):
        open_session(listen="127.0.0.1:7447")
    with pytest.raises(TransportError, match="--drop-rate"):
        FaultInjection(drop_rate=1.0)
