"""The Eclipse Zenoh transport: robots and server as separate processes or hosts.

Key expressions: ``acslam/robot_<i>/{odom,scan,landmarks,heartbeat,truth}`` from robot
``i``, ``acslam/robot_<i>/cmd_vel`` to it, ``acslam/server/status`` from the server.
Payloads are :mod:`acslam.transport.codec` envelopes. Zenoh delivers callbacks on its own
threads; they only decode into locked queues, and the node loops drain those.

Receivers never trust the wire: a payload that does not decode, whose robot id differs
from its key, or names a robot the server does not know is dropped and counted per
reason. Odometry travels with the robot's cumulative dead-reckoned pose; when increments
were lost in between (the next one does not start where the last one ended) the server
end bridges the gap from the two poses, as a ROS ``/odom`` consumer would, so message
loss costs samples, not motion.

``truth`` is the simulation's ground-truth side channel: the other robot simulators read
it so their LiDAR sees this robot, and the run's evaluation records it. The
:class:`~acslam.pipeline.server.Server` never gets it. Fault injection (drop rate, latency) hits
only the sensor topics the server localizes from.
"""

from __future__ import annotations

import json
import re
import threading
import time
from collections import Counter, defaultdict, deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np
import zenoh

from acslam.errors import MessageError, TransportError
from acslam.geometry import between, compose
from acslam.messages import (
    LandmarkObservations,
    LidarScan,
    OdometryIncrement,
    RobotMessage,
    VelocityCommand,
)
from acslam.transport import STATUS_KEY, CommandInbox, robot_key
from acslam.transport.codec import (
    CodecError,
    Heartbeat,
    Odometry,
    StatusBeacon,
    TruthBatch,
    WireMessage,
    decode_timed,
    encode,
)

_ROBOT_KEY = re.compile(r"^acslam/robot_(\d+)/([a-z_]+)$")
_UPLINK = ("odom", "scan", "landmarks", "heartbeat", "truth")


def open_session(
    listen: str | None = None,
    connect: Sequence[str] = (),
    *,
    mode: str = "peer",
    connect_timeout_s: float | None = None,
    timestamping: bool = False,
) -> zenoh.Session:
    """A Zenoh session (``peer``, ``client`` or ``router``) listening on and/or connecting
    to ``tcp/HOST:PORT`` endpoints; a client waits up to ``connect_timeout_s`` for its
    router. Multicast scouting is off: the endpoints given are the whole network, so two
    runs on one machine never meet by accident.
    """
    config = zenoh.Config()
    config.insert_json5("mode", f'"{mode}"')
    config.insert_json5("scouting/multicast/enabled", "false")
    if timestamping:
        config.insert_json5("timestamping/enabled", "true")
    if connect_timeout_s is not None:
        config.insert_json5("connect/timeout_ms", str(round(1000 * connect_timeout_s)))
    for option, endpoints in (("listen", [listen] if listen else []), ("connect", connect)):
        for endpoint in endpoints:
            if not re.match(r"^(tcp|udp|quic|tls)/[^:]+:\d+$", endpoint):
                raise TransportError(f"--{option}: expected tcp/HOST:PORT, got {endpoint!r}")
        if endpoints:
            config.insert_json5(f"{option}/endpoints", json.dumps(list(endpoints)))
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        raise TransportError(f"--{'listen' if listen else 'connect'}: {exc}") from None


def latency_percentiles_ms(latency_s: Mapping[str, list[float]]) -> dict[str, dict[str, float]]:
    """Per topic, the p50 and p95 of latencies measured on arrival, in milliseconds."""
    return {
        topic: {
            "p50_ms": 1000 * float(np.percentile(values, 50)),
            "p95_ms": 1000 * float(np.percentile(values, 95)),
        }
        for topic, values in sorted(latency_s.items())
    }


@dataclass
class LinkStats:
    """What crossed one end of the link: counts, bytes, latency, drops by reason."""

    started_s: float = field(default_factory=time.monotonic)
    messages: Counter = field(default_factory=Counter)
    bytes: Counter = field(default_factory=Counter)
    latency_s: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    dropped: Counter = field(default_factory=Counter)

    def count(self, robot: int, topic: str, size: int, latency_s: float | None = None) -> None:
        self.messages[(robot, topic)] += 1
        self.bytes[(robot, topic)] += size
        if latency_s is not None:
            self.latency_s[topic].append(latency_s)

    def summary(self) -> dict:
        """Per robot and topic: messages and bytes per second; latency p50/p95 (ms)."""
        elapsed_s = max(time.monotonic() - self.started_s, 1e-9)
        per_robot: dict[str, dict] = defaultdict(dict)
        for (robot, topic), size in sorted(self.bytes.items()):
            per_robot[f"robot_{robot}"][topic] = {
                "messages": self.messages[(robot, topic)],
                "bytes_per_s": size / elapsed_s,
            }
        return {
            "elapsed_s": elapsed_s,
            "per_robot": dict(per_robot),
            "latency": latency_percentiles_ms(self.latency_s),
            "dropped": dict(self.dropped),
        }


def _robot_of(key: str, topic: str) -> int:
    match = _ROBOT_KEY.match(key)
    if match is None or match.group(2) != topic:
        raise CodecError(f"unexpected key {key!r}")
    return int(match.group(1))


def _sender(message: WireMessage) -> int:
    if isinstance(message, Odometry):
        return message.increment.robot_id
    return message.robot_id  # type: ignore[union-attr]


class ZenohServerEndpoint:
    """The server's end: robot messages in, commands and status out."""

    def __init__(self, session: zenoh.Session, robot_count: int) -> None:
        self.robot_count = robot_count
        self.stats = LinkStats()
        self._lock = threading.Lock()
        self._inbox: list[RobotMessage] = []
        self._heard: dict[int, tuple[float, Heartbeat]] = {}
        self._truth: dict[int, list[TruthBatch]] = defaultdict(list)
        self._last_odom: dict[int, Odometry] = {}
        self._ignored: set[int] = set()
        self._subscribers = [
            session.declare_subscriber(f"acslam/*/{topic}", partial(self._on_sample, topic))
            for topic in _UPLINK
        ]
        self._commands = {
            i: session.declare_publisher(robot_key(i, "cmd_vel")) for i in range(robot_count)
        }
        self._status = session.declare_publisher(STATUS_KEY)

    def _on_sample(self, topic: str, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        try:
            robot = _robot_of(str(sample.key_expr), topic)
            message, sent_s = decode_timed(payload, topic)
            if _sender(message) != robot or robot >= self.robot_count:
                raise CodecError(f"robot id {_sender(message)} on key of robot {robot}")
        except MessageError as exc:
            with self._lock:
                self.stats.dropped[f"{topic}: {type(exc).__name__}"] += 1
            return
        with self._lock:
            self.stats.count(robot, topic, len(payload), time.time() - sent_s)
            if robot in self._ignored:
                return
            if isinstance(message, Heartbeat):
                self._heard[robot] = (time.monotonic(), message)
            elif isinstance(message, TruthBatch):
                self._truth[robot].append(message)
            elif isinstance(message, Odometry):
                self._add_odometry(robot, message)
            else:
                self._inbox.append(message)  # type: ignore[arg-type]

    def _add_odometry(self, robot: int, message: Odometry) -> None:
        increment = message.increment
        previous = self._last_odom.get(robot)
        if previous is not None:
            if increment.stamp <= previous.increment.stamp:
                self.stats.dropped["odom: stale"] += 1
                return
            if increment.start_stamp != previous.increment.stamp:
                dx, dy, dtheta = between(previous.pose, message.pose)
                increment = OdometryIncrement(
                    robot, increment.stamp, previous.increment.stamp, dx, dy, dtheta
                )
                self.stats.dropped["odom: gap bridged"] += 1
        self._last_odom[robot] = message
        self._inbox.append(increment)

    def receive(self) -> list[RobotMessage]:
        with self._lock:
            messages, self._inbox = self._inbox, []
        return messages

    def stats_summary(self) -> dict:
        """:meth:`LinkStats.summary`, safe while callbacks are still counting."""
        with self._lock:
            return self.stats.summary()

    def reset_stats(self) -> None:
        """Count from now on (the run starts): rates then exclude the wait for robots."""
        with self._lock:
            self.stats = LinkStats()

    def send(self, commands: Iterable[VelocityCommand]) -> None:
        for command in commands:
            if command.robot_id in self._ignored:
                continue
            payload = encode(command)
            self._commands[command.robot_id].put(payload)
            with self._lock:
                self.stats.count(command.robot_id, "cmd_vel", len(payload))

    def publish_status(self, beacon: StatusBeacon) -> None:
        self._status.put(encode(beacon))

    def ignore(self, robot_id: int) -> None:
        """Drop everything from a robot from now on (it was declared lost)."""
        with self._lock:
            self._ignored.add(robot_id)

    def heartbeats(self) -> dict[int, tuple[float, Heartbeat]]:
        """Per robot: monotonic receive time and content of its last heartbeat."""
        with self._lock:
            return dict(self._heard)

    def truth(self) -> dict[int, list[TruthBatch]]:
        with self._lock:
            return {robot: list(batches) for robot, batches in self._truth.items()}


@dataclass(frozen=True)
class FaultInjection:
    """Faults a robot agent injects into its own sensor messages."""

    drop_rate: float = 0.0
    latency_s: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.drop_rate < 1.0:
            raise TransportError(f"--drop-rate: must be in [0, 1), got {self.drop_rate}")
        if not 0.0 <= self.latency_s < 60.0:
            raise TransportError("--latency-ms: must be in [0, 60000)")


class ZenohRobotEndpoint:
    """One robot's end: sensor messages out (through fault injection), commands in."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: int,
        start_pose: np.ndarray,
        faults: FaultInjection,
        rng: np.random.Generator,
    ) -> None:
        self.robot_id = robot_id
        self.faults = faults
        self.stats = LinkStats()
        self._rng = rng
        self._pose = np.asarray(start_pose, dtype=float)
        self._lock = threading.Lock()
        self._commands = CommandInbox()
        self._status: tuple[float, StatusBeacon] | None = None
        self._others: dict[int, np.ndarray] = {}
        self._delayed: deque[tuple[float, str, WireMessage]] = deque()
        self._publishers = {
            topic: session.declare_publisher(robot_key(robot_id, topic)) for topic in _UPLINK
        }
        self._subscribers = [
            session.declare_subscriber(robot_key(robot_id, "cmd_vel"), self._on_command),
            session.declare_subscriber(STATUS_KEY, self._on_status),
            session.declare_subscriber("acslam/*/truth", self._on_truth),
        ]

    @property
    def pose(self) -> np.ndarray:
        """The robot's own dead-reckoned pose (odometry composed from its start)."""
        return self._pose.copy()

    def _receive(self, sample: zenoh.Sample, topic: str) -> WireMessage | None:
        payload = sample.payload.to_bytes()
        try:
            message, sent_s = decode_timed(payload, topic)
        except MessageError as exc:
            with self._lock:
                self.stats.dropped[f"{topic}: {type(exc).__name__}"] += 1
            return None
        with self._lock:
            self.stats.count(self.robot_id, topic, len(payload), time.time() - sent_s)
        return message

    def _on_command(self, sample: zenoh.Sample) -> None:
        message = self._receive(sample, "cmd_vel")
        if isinstance(message, VelocityCommand) and message.robot_id == self.robot_id:
            self._commands.put(message)

    def _on_status(self, sample: zenoh.Sample) -> None:
        message = self._receive(sample, "status")
        if isinstance(message, StatusBeacon):
            with self._lock:
                self._status = (time.monotonic(), message)

    def _on_truth(self, sample: zenoh.Sample) -> None:
        try:
            robot = _robot_of(str(sample.key_expr), "truth")
            message = decode_timed(sample.payload.to_bytes(), "truth")[0]
        except MessageError:
            return
        if isinstance(message, TruthBatch) and message.robot_id == robot != self.robot_id:
            with self._lock:
                self._others[robot] = message.poses[-1]

    def publish(self, message: RobotMessage) -> None:
        """Send a sensor message, unless the injected loss drops it; late if delayed."""
        wire: WireMessage = message
        if isinstance(message, OdometryIncrement):
            self._pose = compose(self._pose, message.delta)
            wire = Odometry(message, self._pose)
        topic = {Odometry: "odom", LidarScan: "scan", LandmarkObservations: "landmarks"}[type(wire)]
        if self.faults.drop_rate and self._rng.random() < self.faults.drop_rate:
            with self._lock:
                self.stats.dropped[f"{topic}: injected"] += 1
            return
        self._delayed.append((time.monotonic() + self.faults.latency_s, topic, wire))
        self.flush()

    def flush(self) -> None:
        """Put every delayed message whose injected latency has passed on the wire."""
        now = time.monotonic()
        while self._delayed and self._delayed[0][0] <= now:
            _, topic, wire = self._delayed.popleft()
            self._put(topic, wire)

    def _put(self, topic: str, wire: WireMessage) -> None:
        payload = encode(wire)
        self._publishers[topic].put(payload)
        with self._lock:
            self.stats.count(self.robot_id, topic, len(payload))

    def stats_summary(self) -> dict:
        """:meth:`LinkStats.summary`, safe while callbacks are still counting."""
        with self._lock:
            return self.stats.summary()

    def heartbeat(self, stamp: float) -> None:
        self._put("heartbeat", Heartbeat(self.robot_id, stamp, self._pose))

    def publish_truth(self, batch: TruthBatch) -> None:
        self._put("truth", batch)

    def receive_commands(self) -> list[VelocityCommand]:
        return self._commands.take()

    def status(self) -> tuple[float, StatusBeacon] | None:
        """Monotonic receive time and content of the server's last status, if any."""
        with self._lock:
            return self._status

    def other_poses(self) -> dict[int, np.ndarray]:
        """The latest true pose of every other robot heard on the truth channel."""
        with self._lock:
            return dict(self._others)
