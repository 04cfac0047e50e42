"""The wire format: exact round trips, and every malformed payload becomes a CodecError."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from acslam.errors import MessageError
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, VelocityCommand
from acslam.transport.codec import (
    FORMAT_VERSION,
    CodecError,
    Heartbeat,
    Odometry,
    StatusBeacon,
    TruthBatch,
    decode,
    decode_timed,
    encode,
)


def _scan() -> LidarScan:
    angles = np.linspace(-math.pi, math.pi, 360, endpoint=False)
    ranges = np.random.default_rng(0).uniform(0.1, 7.9, 360)
    ranges[10], ranges[11] = np.inf, 0.0
    return LidarScan(2, 12.34, angles, ranges, 8.0)


def test_scan_round_trip_is_exact_and_compact() -> None:
    scan = _scan()
    payload = encode(scan)
    back = decode(payload, "scan")
    assert isinstance(back, LidarScan)
    assert back.robot_id == 2 and back.stamp == 12.34 and back.range_max_m == 8.0
    np.testing.assert_array_equal(back.ranges, scan.ranges)  # inf and 0 survive
    np.testing.assert_array_equal(back.angles, scan.angles)
    # Raw float64 ranges; the evenly spaced angles travel as their two ends.
    assert 360 * 8 < len(payload) < 360 * 8 + 100


def test_uneven_angles_travel_raw_and_exact() -> None:
    angles = np.sort(np.random.default_rng(1).uniform(-1.0, 1.0, 50))
    scan = LidarScan(0, 1.0, angles, np.ones(50), 8.0)
    payload = encode(scan)
    assert len(payload) > 2 * 50 * 8
    np.testing.assert_array_equal(decode(payload, "scan").angles, angles)


@pytest.mark.parametrize(
    ("message", "kind"),
    [
        (Odometry(OdometryIncrement(1, 2.0, 1.95, 0.01, -0.002, 0.003), [1.0, 2.0, 0.5]), "odom"),
        (LandmarkObservations(0, 3.0, np.arange(12.0).reshape(4, 3)), "landmarks"),
        (
            LandmarkObservations(
                0, 3.0, np.ones((2, 3)), np.arange(64, dtype=np.uint8).reshape(2, 32)
            ),
            "landmarks",
        ),
        (LandmarkObservations(0, 3.0, np.zeros((0, 3))), "landmarks"),
        (VelocityCommand(4, 9.5, 0.22, -1.25), "cmd_vel"),
        (Heartbeat(1, 7.0, np.array([3.0, 4.0, -2.0])), "heartbeat"),
        (StatusBeacon(10.5, False, (1, 2)), "status"),
        (TruthBatch(0, [0.0, 0.02], [[1.0, 2.0, 0.1], [1.0, 2.01, 0.1]], [0, 3]), "truth"),
    ],
)
def test_every_kind_round_trips(message: object, kind: str) -> None:
    back, sent_s = decode_timed(encode(message), kind)
    assert type(back) is type(message)
    assert sent_s > 1.7e9  # wall-clock seconds of the encoding
    for name, value in vars(message).items():
        got = getattr(back, name)
        if isinstance(value, OdometryIncrement):
            assert vars(got) == vars(value)
        elif value is None or isinstance(value, (int, float, bool, tuple)):
            assert got == value
        else:
            np.testing.assert_array_equal(got, value)


def _body(payload: bytes) -> dict:
    return msgpack.unpackb(payload)


def _pack(body: dict) -> bytes:
    return msgpack.packb(body, use_bin_type=True)


def _with_nan_range() -> bytes:
    body = _body(encode(_scan()))
    ranges = np.frombuffer(body["g"][2]).copy()
    ranges[5] = np.nan
    body["g"][2] = ranges.tobytes()
    return _pack(body)


def _with(field: str, value: object) -> bytes:
    body = _body(encode(_scan()))
    body[field] = value
    return _pack(body)


@pytest.mark.parametrize(
    ("payload", "problem"),
    [
        (b"", "msgpack"),
        (b"\xc1\xff garbage", "msgpack"),
        (_pack([1, 2, 3]), "not a map"),
        (_with("v", FORMAT_VERSION + 1), "version"),
        (_with("k", "odom"), "kind"),
        (_with_nan_range(), "NaN"),
        (_with("g", ["<f8", [361], b"\x00" * 360 * 8]), "byte length"),
        (_with("g", ["<f4", [360], b"\x00" * 360 * 4]), "dtype"),
        (_with("a", ["<f8", [2], b"\x00" * 16]), "equal length"),
        (_with("a", ["lin", 0.0, 1.0, 10**9]), "beam count"),
        (_with("a", ["lin", 0.0, "x", 360]), "malformed"),
        (_with("m", float("nan")), "range_max_m"),
        (_with("r", -1), "robot_id"),
        (_with("s", "soon"), "malformed"),
    ],
)
def test_malformed_payloads_raise_one_message_error(payload: bytes, problem: str) -> None:
    # CodecError for the wire, MessageError (its base) from the message's own checks:
    # the receiver drops and counts both alike.
    with pytest.raises(MessageError, match=problem):
        decode(payload, "scan")


def test_nan_in_odometry_and_truth_is_rejected() -> None:
    odom = _body(encode(Odometry(OdometryIncrement(0, 1.0, 0.9, 0.1, 0, 0), [0.0, 0.0, 0.0])))
    odom["d"][0] = float("nan")
    with pytest.raises(MessageError, match="finite"):
        decode(_pack(odom), "odom")
    odom["d"][0] = 0.1
    odom["p"] = [0.0, float("inf"), 0.0]
    with pytest.raises(CodecError, match="pose"):
        decode(_pack(odom), "odom")
