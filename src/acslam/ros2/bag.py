"""ROS bags without ROS: read ROS 1 ``.bag`` files and rosbag2 recordings (an ``.mcap`` or
``.db3`` storage file, or the folder holding them) as ROS 2 messages, and write rosbag2
recordings as one MCAP file.

Messages are decoded with acslam's own ROS 2 types (:func:`acslam.ros2.wire.typestore`),
never with the definitions a bag embeds: some writers store placeholders there (the
sqlite3 recordings of rosbag2's own tests do). ROS 1 messages are converted to CDR first,
which drops what ROS 2 removed (the header's ``seq``). A rosbag2 folder is read through its
storage files, not its ``metadata.yaml``: a metadata QoS that differs from the storage's
makes rosbags match no message at all, silently.

A file that is not a readable bag, or a message that does not decode, raises one
:class:`~acslam.errors.DataError` naming the file.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag2 import Reader as Ros2Reader
from rosbags.rosbag2 import StoragePlugin, Writer

from acslam.errors import AcslamError, DataError
from acslam.ros2 import convert, wire
from acslam.ros2.convert import Message

ROS2_STORAGE_SUFFIXES = (".mcap", ".db3")
ROS1_SUFFIX = ".bag"

LATCHED = Qos(
    QosHistory.KEEP_LAST,
    1,
    QosReliability.RELIABLE,
    QosDurability.TRANSIENT_LOCAL,
    QosTime(0, 0),
    QosTime(0, 0),
    QosLiveliness.AUTOMATIC,
    QosTime(0, 0),
    False,
)
"""Transient local, depth 1: what ``tf_static`` and ``/map`` are published with, so a late
subscriber (RViz, ``ros2 bag play``'s listeners) still gets the last message."""


@dataclass(frozen=True)
class BagMessage:
    """One decoded message: its topic and type, the time it was recorded (ns) and the
    rosbags message object."""

    topic: str
    msgtype: str
    log_time_ns: int
    message: Message


@contextmanager
def _reading(path: Path) -> Iterator[None]:
    """rosbags' own errors as one DataError naming the file. A damaged file raises
    whatever the parser trips on (ReaderError, struct and Unicode errors, TypeError...),
    so every exception from reading it is the file's fault."""
    try:
        yield
    except AcslamError:
        raise
    except Exception as exc:
        raise DataError(path, f"not a readable bag ({type(exc).__name__}: {exc})") from None


def _storage_files(path: Path) -> list[Path]:
    """The files of the bag at ``path``: itself, or a rosbag2 folder's storage files."""
    if not path.exists():
        raise DataError(path, "bag not found")
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix in ROS2_STORAGE_SUFFIXES)
        if not files:
            raise DataError(path, "no .mcap or .db3 storage file in this rosbag2 folder")
        return files
    if path.suffix not in (ROS1_SUFFIX, *ROS2_STORAGE_SUFFIXES):
        raise DataError(path, "not a bag: expected a .bag, .mcap or .db3 file or a rosbag2 folder")
    return [path]


class BagReader:
    """A bag open for reading: :attr:`topics` and decoded :meth:`messages`.

    ``distro`` names the ROS 2 message types decoded into (the ones acslam reads are the
    same in every distro).
    """

    def __init__(self, path: str | Path, distro: str = wire.DEFAULT_DISTRO) -> None:
        self.path = Path(path)
        self.distro = distro
        self._readers: list[tuple[Path, Ros1Reader | Ros2Reader]] = []
        self.topics: dict[str, str] = {}
        """Topic -> message type (``pkg/msg/Name``, ROS 1 types named the ROS 2 way)."""
        self.counts: dict[str, int] = {}
        """Topic -> number of messages."""
        try:
            for file in _storage_files(self.path):
                reader_type = Ros1Reader if file.suffix == ROS1_SUFFIX else Ros2Reader
                with _reading(file):
                    reader = reader_type(file)
                    reader.open()
                    self._readers.append((file, reader))
                    for connection in reader.connections:
                        self.topics.setdefault(connection.topic, connection.msgtype)
                        count = self.counts.get(connection.topic, 0) + connection.msgcount
                        self.counts[connection.topic] = count
        except AcslamError:
            self.close()
            raise

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        """The messages of ``topics`` (default: all), decoded, file by file in the order
        each storage file yields them (by log time)."""
        wanted = set(self.topics if topics is None else topics) & set(self.topics)
        store = wire.typestore(self.distro)
        for topic in sorted(wanted):
            if self.topics[topic] not in store.types:
                raise DataError(
                    self.path,
                    f"topic {topic}: message type {self.topics[topic]} is not a ROS 2 "
                    f"{self.distro} type acslam knows",
                )
        for file, reader in self._readers:
            ros1 = file.suffix == ROS1_SUFFIX
            with _reading(file):
                connections = [c for c in reader.connections if c.topic in wanted]
                if not connections:
                    continue
                for connection, log_time_ns, raw in reader.messages(connections=connections):
                    topic, msgtype = connection.topic, connection.msgtype
                    try:
                        payload = store.ros1_to_cdr(raw, msgtype) if ros1 else raw
                        message = wire.decode_cdr(payload, msgtype, self.distro)
                    except Exception as exc:  # CodecError, or rosbags' on a ROS 1 message
                        raise DataError(
                            file, f"a {msgtype} message on {topic} does not decode ({exc})"
                        ) from None
                    yield BagMessage(topic, msgtype, log_time_ns, message)

    def close(self) -> None:
        for _, reader in self._readers:
            reader.close()
        self._readers = []

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exception: object) -> None:
        self.close()


class BagWriter:
    """A rosbag2 recording in MCAP storage, written as the one file ``path`` (``.mcap``):
    what Foxglove opens, and what ``ros2 bag`` reads as a bag (its metadata is inside).

    Connections are added when a topic is first written; a latched topic is recorded with
    transient-local QoS. The file appears at :meth:`close`, replacing any earlier one; until
    then it is written in a hidden folder beside it.
    """

    def __init__(self, path: str | Path, distro: str = wire.DEFAULT_DISTRO) -> None:
        self.path = Path(path)
        if self.path.suffix != ".mcap":
            raise DataError(self.path, "a bag is written as an .mcap file")
        self.distro = distro
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._folder = Path(tempfile.mkdtemp(prefix=".acslam-bag-", dir=self.path.parent))
        self._writer = Writer(
            self._folder / self.path.stem, version=9, storage_plugin=StoragePlugin.MCAP
        )
        self._writer.open()
        self._connections: dict[str, object] = {}

    def write(self, topic: str, message: Message, stamp_s: float, latched: bool = False) -> None:
        """Record ``message`` on ``topic`` at ``stamp_s`` (its header stamp, if it has one)."""
        msgtype = message.__msgtype__
        connection = self._connections.get(topic)
        if connection is None:
            connection = self._writer.add_connection(
                topic,
                msgtype,
                typestore=wire.typestore(self.distro),
                offered_qos_profiles=[LATCHED] if latched else [],
            )
            self._connections[topic] = connection
        stamp = convert.ros_time(stamp_s, self.distro)
        log_time_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        self._writer.write(connection, log_time_ns, wire.encode_cdr(message, msgtype, self.distro))

    def close(self) -> None:
        """Finish the file and move it to :attr:`path`."""
        self._writer.close()
        os.replace(self._folder / self.path.stem / f"{self.path.stem}.mcap", self.path)
        shutil.rmtree(self._folder)

    def discard(self) -> None:
        """Drop what was written: no file appears."""
        self._writer.abort()
        shutil.rmtree(self._folder)

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        """Write the file, unless an exception ends the writing."""
        if exc_type is None:
            self.close()
        else:
            self.discard()
