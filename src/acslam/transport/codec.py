"""Wire format of the distributed run: msgpack envelopes with raw little-endian numpy bytes.

Every payload is a msgpack map ``{"v": FORMAT_VERSION, "k": kind, "w": wall time sent,
...fields}``; arrays travel as ``[dtype, shape, bytes]`` and evenly spaced beam angles
as their two ends, so a 360-beam scan costs its 2.9 kB of float64 ranges plus about 70
bytes, not a text rendering. Decoding rebuilds the
validated dataclasses of :mod:`acslam.messages`, so a NaN, a wrong shape, a foreign
version or plain garbage raises one :class:`CodecError` naming the problem, and the
receiver drops and counts the payload instead of crashing.

Besides the robot <-> server messages the wire carries: :class:`Odometry` (an increment
plus the robot's cumulative dead-reckoned pose, so a receiver can bridge lost increments
like a ROS ``/odom`` consumer), :class:`Heartbeat`, :class:`StatusBeacon` (server ->
robots) and :class:`TruthBatch` (the evaluation-only ground-truth side channel).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import msgpack
import numpy as np

from acslam.errors import CodecError, MessageError
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, VelocityCommand

FORMAT_VERSION = 1
_DTYPES = {"<f8": np.dtype("<f8"), "|u1": np.dtype("u1"), "<i8": np.dtype("<i8")}


def _finite_pose(kind: str, pose: np.ndarray) -> np.ndarray:
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (3,) or not np.isfinite(pose).all():
        raise CodecError(f"{kind}.pose: must be 3 finite numbers")
    return pose


@dataclass(frozen=True)
class Odometry:
    """An odometry increment and the robot's dead-reckoned pose at its ``stamp``."""

    increment: OdometryIncrement
    pose: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "pose", _finite_pose("Odometry", self.pose))


@dataclass(frozen=True)
class Heartbeat:
    """A robot is alive; ``pose`` is its own dead-reckoned pose (a restarted server starts
    the robot there)."""

    robot_id: int
    stamp: float
    pose: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.robot_id, int) or self.robot_id < 0:
            raise CodecError("Heartbeat.robot_id: must be a non-negative integer")
        if not math.isfinite(self.stamp):
            raise CodecError("Heartbeat.stamp: must be finite")
        object.__setattr__(self, "pose", _finite_pose("Heartbeat", self.pose))


@dataclass(frozen=True)
class StatusBeacon:
    """The server's state, published every control period."""

    stamp: float
    finished: bool
    lost: tuple[int, ...]

    def __post_init__(self) -> None:
        if not math.isfinite(self.stamp):
            raise CodecError("StatusBeacon.stamp: must be finite")


@dataclass(frozen=True)
class TruthBatch:
    """True poses ``[x, y, theta]`` of one robot at ``stamps`` and its cumulative contact
    counts (walls, robots): for evaluation and for the other robots' LiDAR only."""

    robot_id: int
    stamps: np.ndarray
    poses: np.ndarray
    collisions: np.ndarray

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps, dtype=float)
        poses = np.asarray(self.poses, dtype=float)
        collisions = np.asarray(self.collisions, dtype=np.int64)
        if stamps.ndim != 1 or poses.shape != (len(stamps), 3) or collisions.shape != (2,):
            raise CodecError("TruthBatch: stamps (K,), poses (K, 3), collisions (2,) required")
        if not (np.isfinite(stamps).all() and np.isfinite(poses).all()):
            raise CodecError("TruthBatch: stamps and poses must be finite")
        object.__setattr__(self, "stamps", stamps)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "collisions", collisions)


WireMessage = (
    Odometry
    | LidarScan
    | LandmarkObservations
    | VelocityCommand
    | Heartbeat
    | StatusBeacon
    | TruthBatch
)


def _array(value: np.ndarray, dtype: str = "<f8") -> list:
    array = np.ascontiguousarray(value, dtype=_DTYPES[dtype])
    return [dtype, list(array.shape), array.tobytes()]


def _unarray(field: Any) -> np.ndarray:
    if not (isinstance(field, list) and len(field) == 3):
        raise CodecError("array field: expected [dtype, shape, bytes]")
    dtype_name, shape, data = field
    dtype = _DTYPES.get(dtype_name)
    if dtype is None or not isinstance(data, bytes) or not isinstance(shape, list):
        raise CodecError(f"array field: unsupported dtype {dtype_name!r} or malformed field")
    if any(not isinstance(n, int) or n < 0 for n in shape):
        raise CodecError("array field: shape must be non-negative integers")
    if math.prod(shape) * dtype.itemsize != len(data):
        raise CodecError("array field: byte length does not match shape")
    return np.frombuffer(data, dtype=dtype).reshape(shape).copy()


def _angles(angles: np.ndarray) -> list:
    """Evenly spaced beam angles (every LiDAR's) as ``["lin", first, last, n]`` when that
    rebuilds them bit for bit, else raw: halves a scan's size, never changes a value."""
    n = len(angles)
    if n >= 2 and np.array_equal(np.linspace(angles[0], angles[-1], n), angles):
        return ["lin", float(angles[0]), float(angles[-1]), n]
    return _array(angles)


def _unangles(field: Any, beams: int) -> np.ndarray:
    if isinstance(field, list) and len(field) == 4 and field[0] == "lin":
        _, first, last, n = field
        if n != beams:
            raise CodecError("LidarScan.angles: beam count differs from the ranges'")
        return np.linspace(float(first), float(last), n)
    return _unarray(field)


def encode(message: WireMessage) -> bytes:
    """Serialize one wire message (stamped with the wall time it is encoded at)."""
    body: dict[str, Any]
    match message:
        case Odometry(increment=m, pose=pose):
            body = {
                "k": "odom",
                "r": m.robot_id,
                "s": m.stamp,
                "s0": m.start_stamp,
                "d": [m.dx, m.dy, m.dtheta],
                "p": pose.tolist(),
            }
        case LidarScan():
            body = {
                "k": "scan",
                "r": message.robot_id,
                "s": message.stamp,
                "a": _angles(message.angles),
                "g": _array(message.ranges),
                "m": message.range_max_m,
            }
        case LandmarkObservations():
            descriptors = message.descriptors
            body = {
                "k": "landmarks",
                "r": message.robot_id,
                "s": message.stamp,
                "p": _array(message.points),
                "x": None if descriptors is None else _array(descriptors, "|u1"),
            }
        case VelocityCommand():
            body = {
                "k": "cmd_vel",
                "r": message.robot_id,
                "s": message.stamp,
                "c": [message.v, message.omega],
            }
        case Heartbeat():
            body = {"k": "heartbeat", "r": message.robot_id, "s": message.stamp}
            body["p"] = message.pose.tolist()
        case StatusBeacon():
            body = {
                "k": "status",
                "s": message.stamp,
                "f": message.finished,
                "l": list(message.lost),
            }
        case TruthBatch():
            body = {
                "k": "truth",
                "r": message.robot_id,
                "t": _array(message.stamps),
                "p": _array(message.poses),
                "c": _array(message.collisions, "<i8"),
            }
        case _:
            raise TypeError(f"cannot encode {type(message).__name__}")
    return msgpack.packb({"v": FORMAT_VERSION, "w": time.time(), **body}, use_bin_type=True)


def _envelope(payload: bytes) -> dict:
    try:
        body = msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # msgpack raises several unrelated types on garbage
        raise CodecError(f"not a msgpack payload: {type(exc).__name__}") from None
    if not isinstance(body, dict):
        raise CodecError("payload is not a map")
    if body.get("v") != FORMAT_VERSION:
        raise CodecError(f"format version {body.get('v')!r}, expected {FORMAT_VERSION}")
    return body


def decode(payload: bytes, kind: str) -> WireMessage:
    """Parse and validate one payload that must be of ``kind`` (the topic it came on)."""
    return decode_timed(payload, kind)[0]


def decode_timed(payload: bytes, kind: str) -> tuple[WireMessage, float]:
    """:func:`decode`, plus the wall time the payload was encoded at (for latency)."""
    body = _envelope(payload)
    if body.get("k") != kind:
        raise CodecError(f"payload kind {body.get('k')!r} on a {kind!r} topic")
    try:
        return _build(kind, body), float(body["w"])
    except MessageError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise CodecError(f"{kind}: malformed field ({type(exc).__name__}: {exc})") from None


def _build(kind: str, b: dict) -> WireMessage:
    match kind:
        case "odom":
            dx, dy, dtheta = b["d"]
            increment = OdometryIncrement(b["r"], float(b["s"]), float(b["s0"]), dx, dy, dtheta)
            return Odometry(increment, np.array(b["p"], dtype=float))
        case "scan":
            ranges = _unarray(b["g"])
            angles = _unangles(b["a"], len(ranges))
            return LidarScan(b["r"], float(b["s"]), angles, ranges, float(b["m"]))
        case "landmarks":
            descriptors = None if b["x"] is None else _unarray(b["x"])
            return LandmarkObservations(b["r"], float(b["s"]), _unarray(b["p"]), descriptors)
        case "cmd_vel":
            v, omega = b["c"]
            return VelocityCommand(b["r"], float(b["s"]), float(v), float(omega))
        case "heartbeat":
            return Heartbeat(b["r"], float(b["s"]), np.array(b["p"], dtype=float))
        case "status":
            return StatusBeacon(float(b["s"]), bool(b["f"]), tuple(int(i) for i in b["l"]))
        case "truth":
            return TruthBatch(b["r"], _unarray(b["t"]), _unarray(b["p"]), _unarray(b["c"]))
    raise CodecError(f"unknown kind {kind!r}")
