"""ROS bags without ROS: read ROS 1 ``.bag`` files and rosbag2 recordings (an ``.mcap`` or
``.db3`` storage file, or the folder holding them) as ROS 2 messages, and write rosbag2
recordings as one MCAP file, or hold one in memory to replay as it would be read back.

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


def _log_time_ns(stamp_s: float, distro: str) -> int:
    """The time a message stamped ``stamp_s`` is recorded at: its ROS time, in ns."""
    stamp = convert.ros_time(stamp_s, distro)
    return stamp.sec * 1_000_000_000 + stamp.nanosec


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
        log_time_ns = _log_time_ns(stamp_s, self.distro)
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


class MemoryBag:
    """A rosbag2 recording held in memory: written as :class:`BagWriter` writes one and
    read as :class:`BagReader` reads it back (by log time, equal times in the order
    written), without the file. It reads the same messages as the file: a message built
    by :mod:`acslam.ros2.convert` holds the values its CDR carries, and CDR and MCAP store
    them exactly."""

    def __init__(self, path: str | Path, distro: str = wire.DEFAULT_DISTRO) -> None:
        self.path = Path(path)
        """What the recording is named by in messages and errors (no file is written)."""
        self.distro = distro
        self.topics: dict[str, str] = {}
        """Topic -> message type, as :attr:`BagReader.topics`."""
        self.counts: dict[str, int] = {}
        """Topic -> number of messages."""
        self._messages: list[BagMessage] = []

    def write(self, topic: str, message: Message, stamp_s: float, latched: bool = False) -> None:
        """Record ``message`` on ``topic`` at ``stamp_s``, as :meth:`BagWriter.write`
        (``latched`` only matters to a file's subscribers)."""
        self.topics.setdefault(topic, message.__msgtype__)
        self.counts[topic] = self.counts.get(topic, 0) + 1
        log_time_ns = _log_time_ns(stamp_s, self.distro)
        self._messages.append(BagMessage(topic, message.__msgtype__, log_time_ns, message))

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        """The messages of ``topics`` (default: all) by log time, as :meth:`BagReader.messages`."""
        wanted = set(self.topics if topics is None else topics)
        for item in sorted(self._messages, key=lambda item: item.log_time_ns):
            if item.topic in wanted:
                yield item
