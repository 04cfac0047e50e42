"""A ROS 2 node on a Zenoh session, speaking rmw_zenoh's wire format (or that of
zenoh-bridge-ros2dds): what lets acslam talk to ROS 2 robots without a ROS install.

Publishers put CDR payloads with rmw_zenoh's attachment (sequence number, source
timestamp, GID) on the data key of their topic, and announce themselves, and the node,
with liveliness tokens, so ``ros2 node list`` and ``ros2 topic list`` on the robots see
them. A transient-local publisher (``/map``) keeps its last samples in a zenoh-ext
advanced publisher's cache, which is how rmw_zenoh serves late joiners; a transient-local
subscription asks publishers' caches for their history. In bridge mode the keys are the
bridge's (topic name only), with no attachment and no tokens (the bridge announces
itself to the DDS side).

Callbacks run on Zenoh's threads: a subscription decodes there and hands the message to
its callback; a payload that does not decode is counted by reason and dropped, never
raised.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import zenoh
from zenoh import ext

from acslam.errors import CodecError, TransportError
from acslam.ros2 import wire
from acslam.transport.zenoh_link import open_session

HEARTBEAT_PERIOD_S = 0.5
"""Sporadic heartbeat of a reliable transient-local publisher (rmw_zenoh's 500 ms), by
which subscribers notice samples they missed."""


@dataclass(frozen=True)
class Ros2Options:
    """How acslam appears on a ROS 2 network."""

    domain_id: int = 0
    distro: str = "jazzy"
    attachment: str = "positional"
    bridge: bool = False
    bridge_namespace: str = "/"

    def __post_init__(self) -> None:
        if self.distro not in wire.DISTROS:
            raise TransportError(f"--distro: expected one of {', '.join(wire.DISTROS)}")
        if self.attachment not in wire.ATTACHMENT_FORMATS:
            raise TransportError(
                f"--attachment: expected one of {', '.join(wire.ATTACHMENT_FORMATS)}"
            )
        if not 0 <= self.domain_id <= 232:
            raise TransportError(f"--domain-id: must be in [0, 232], got {self.domain_id}")

    def key(self, topic: str, msgtype: str) -> str:
        """The Zenoh key expression samples of ``topic`` travel on."""
        if self.bridge:
            return wire.bridge_key(topic, self.bridge_namespace)
        return wire.topic_key(self.domain_id, topic, msgtype, self.distro)


def open_ros2_session(
    *, connect: Sequence[str] = (), listen: str | None = None, timeout_s: float = 60.0
) -> zenoh.Session:
    """A session that connects as a client to a robot's Zenoh router (``rmw_zenohd`` or
    the bridge, ``tcp/HOST:7447``), waiting up to ``timeout_s`` for it to come up, or,
    with ``listen``, is itself the router the robots connect to. Timestamping is on, as
    rmw_zenoh has it on every session (the advanced publishers need it)."""
    return open_session(
        listen,
        connect,
        mode="router" if listen is not None else "client",
        connect_timeout_s=None if listen is not None else timeout_s,
        timestamping=True,
    )


@dataclass
class TopicStats:
    """What crossed one node: messages and bytes per topic, drops by reason."""

    messages: Counter[str] = field(default_factory=Counter)
    bytes: Counter[str] = field(default_factory=Counter)
    dropped: Counter[str] = field(default_factory=Counter)
    latency_s: dict[str, list[float]] = field(default_factory=dict)
    drop_examples: dict[str, str] = field(default_factory=dict)

    def merge(self, other: TopicStats) -> None:
        self.messages.update(other.messages)
        self.bytes.update(other.bytes)
        self.dropped.update(other.dropped)
        for topic, values in other.latency_s.items():
            self.latency_s.setdefault(topic, []).extend(values)
        self.drop_examples.update(other.drop_examples)


class Ros2Publisher:
    """Puts one topic's messages, with rmw_zenoh's attachment."""

    def __init__(self, node: Ros2Node, topic: str, msgtype: str, qos: wire.Qos) -> None:
        self.node = node
        self.topic = topic
        self.msgtype = msgtype
        options = node.options
        key = options.key(topic, msgtype)
        entity_id = node.next_entity_id()
        token = wire.entity_token(
            options.domain_id, node.zid, node.node_id, entity_id, "MP", node.namespace,
            node.name, topic, msgtype, options.distro, qos,
        )  # fmt: skip
        self.gid = wire.gid_of(token)
        self._sequence = itertools.count(1)
        if qos.transient_local:
            self._publisher: Any = ext.declare_advanced_publisher(
                node.session,
                key,
                cache=ext.CacheConfig(qos.depth),
                publisher_detection=True,
                sample_miss_detection=ext.MissDetectionConfig(
                    heartbeat=None, sporadic_heartbeat=HEARTBEAT_PERIOD_S
                ),
                reliability=zenoh.Reliability.RELIABLE,
            )
        else:
            self._publisher = node.session.declare_publisher(key)
        self._token = None if options.bridge else node.session.liveliness().declare_token(token)

    def put(self, message: Any) -> int:
        """Serialize and send ``message``; returns the payload's size in bytes."""
        options = self.node.options
        payload = wire.encode_cdr(message, self.msgtype, options.distro)
        attachment = None
        if not options.bridge:
            stamp = wire.Attachment(next(self._sequence), time.time_ns(), self.gid)
            attachment = wire.encode_attachment(stamp, options.attachment)
        self._publisher.put(payload, attachment=attachment)
        self.node.count(self.topic, len(payload))
        return len(payload)

    def close(self) -> None:
        if self._token is not None:
            self._token.undeclare()
        self._publisher.undeclare()


class Ros2Node:
    """A node named ``name`` in ``namespace`` on ``session``; creates its publishers and
    subscriptions and keeps their statistics."""

    _ids = itertools.count()

    def __init__(
        self, session: zenoh.Session, name: str, namespace: str, options: Ros2Options
    ) -> None:
        self.session = session
        self.name = name
        self.namespace = namespace
        self.options = options
        self.zid = str(session.zid())
        self.node_id = next(self._ids)
        self.stats = TopicStats()
        self._lock = threading.Lock()
        self._closing: list[Any] = []
        if not options.bridge:
            token = wire.node_token(options.domain_id, self.zid, self.node_id, namespace, name)
            self._closing.append(session.liveliness().declare_token(token))

    def next_entity_id(self) -> int:
        return next(self._ids)

    def count(self, topic: str, size: int, latency_s: float | None = None) -> None:
        with self._lock:
            self.stats.messages[topic] += 1
            self.stats.bytes[topic] += size
            if latency_s is not None:
                self.stats.latency_s.setdefault(topic, []).append(latency_s)

    def drop(self, topic: str, reason: str, detail: Exception | None = None) -> None:
        """Count a message of ``topic`` dropped for ``reason`` (a few fixed words, so
        counts add up); ``detail``, the last such error, is kept as an example."""
        key = f"{topic}: {reason}"
        with self._lock:
            self.stats.dropped[key] += 1
            if detail is not None:
                self.stats.drop_examples[key] = str(detail)

    def statistics(self) -> TopicStats:
        """A copy, safe while callbacks are still counting."""
        with self._lock:
            copy = TopicStats()
            copy.merge(self.stats)
            return copy

    def publisher(self, topic: str, msgtype: str, qos: wire.Qos | None = None) -> Ros2Publisher:
        publisher = Ros2Publisher(self, topic, msgtype, qos or wire.Qos())
        self._closing.append(publisher)
        return publisher

    def subscribe(
        self,
        topic: str,
        msgtype: str,
        callback: Callable[[Any], None],
        qos: wire.Qos | None = None,
    ) -> None:
        """Call ``callback`` with each decoded message of ``topic`` (on a Zenoh thread).

        A payload that does not decode, or (rmw_zenoh mode) arrives without a valid
        attachment, is dropped and counted under ``"<topic>: <reason>"``.
        """
        qos = qos or wire.Qos()
        options = self.options
        key = options.key(topic, msgtype)

        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            latency_s = None
            if not options.bridge:
                if sample.attachment is None:
                    self.drop(topic, "no rmw_zenoh attachment")
                    return
                try:
                    stamp = wire.decode_attachment(sample.attachment.to_bytes())
                except CodecError as exc:
                    self.drop(topic, "bad attachment", exc)
                    return
                latency_s = time.time() - stamp.source_timestamp_ns * 1e-9
            try:
                message = wire.decode_cdr(payload, msgtype, options.distro)
            except CodecError as exc:
                self.drop(topic, "payload does not decode", exc)
                return
            self.count(topic, len(payload), latency_s)
            callback(message)

        if qos.transient_local:
            subscriber: Any = ext.declare_advanced_subscriber(
                self.session,
                key,
                on_sample,
                history=ext.HistoryConfig(detect_late_publishers=True, max_samples=qos.depth),
                recovery=ext.RecoveryConfig(heartbeat=True),
                subscriber_detection=True,
            )
        else:
            subscriber = self.session.declare_subscriber(key, on_sample)
        self._closing.append(subscriber)
        if not options.bridge:
            token = wire.entity_token(
                options.domain_id, self.zid, self.node_id, self.next_entity_id(), "MS",
                self.namespace, self.name, topic, msgtype, options.distro, qos,
            )  # fmt: skip
            self._closing.append(self.session.liveliness().declare_token(token))

    def close(self) -> None:
        """Undeclare everything (tokens vanish, so the robots' graph forgets the node)."""
        for item in reversed(self._closing):
            if isinstance(item, Ros2Publisher):
                item.close()
            else:
                item.undeclare()
        self._closing.clear()
