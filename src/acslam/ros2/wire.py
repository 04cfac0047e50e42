"""The rmw_zenoh wire format as pure functions (no Zenoh session is opened here).

An rmw_zenoh publisher puts each message as CDR (a 4-byte encapsulation header, then the
body) on the data key ``<domain>/<topic>/<dds type>/<type hash>``, with a mandatory
attachment (sequence number, source timestamp, 16-byte publisher GID): a subscriber drops
samples without one. The ROS graph (``ros2 node list``, ``ros2 topic info``, matched
counts) is built from liveliness tokens under ``@ros2_lv``; data flows without them.

Which design each part follows (ros2/rmw_zenoh release trees, read at the commits of the
bloom release repository ros2-gbp/rmw_zenoh-release, tag ``upstream/<version>``; paths
are under ``rmw_zenoh_cpp/src/detail/``):

- data key expressions, liveliness tokens and their QoS string: Jazzy 0.2.10,
  commit 70d155975adf9b2a1a920c02b247d9f2b6e6467f, ``liveliness_utils.cpp``
  (``strip_slashes``, ``Entity``, ``qos_to_keyexpr``) and ``qos.cpp`` (the defaults);
  Kilted 0.6.7 (a6ea04f606ee48b62977421bdcab39c823d67454) is byte-identical. Humble 0.1.9
  (d60045d71ca16efcc7b98ac9bd076426b9e8340e) has the same formats but writes the literal
  ``TypeHashNotSupported`` instead of a hash (``rmw_publisher_data.cpp``).
- DDS type names: ``type_support_common.cpp`` ``_create_type_name`` at 0.2.10; type hashes
  (``RIHS01_`` + sha256 of the rosidl type description, via rosbags ``hash_rihs01``):
  ``rmw_publisher_data.cpp`` at 0.2.10.
- positional attachment (33 bytes): Jazzy 0.2.4, commit
  08bd12da7fe1b2f279f765fbdf249356ee10994e, ``attachment_helpers.cpp`` (PR #605; Humble
  0.1.2 #606, Rolling #601). Every current release uses it.
- legacy key/value attachment (77 bytes): Jazzy 0.2.3, commit
  250295bd3f1971a74d088b8a3be967478bd48886, ``attachment_helpers.cpp`` (Jazzy 0.2.0-0.2.3,
  Humble 0.1.0-0.1.1).
- CDR payload: ``cdr.cpp`` and ``type_support.cpp`` at 0.2.10 (Fast-CDR, header
  ``00 01 00 00``).
- zenoh-bridge-ros2dds keys: eclipse-zenoh/zenoh-plugin-ros2dds commit
  09d68c049936b7d2642eddb2457b47a19903ebdd, ``ros2_utils.rs`` ``ros2_name_to_key_expr``
  (no domain, type or hash; the raw DDS sample as payload; no attachment).
"""

from __future__ import annotations

import functools
import hashlib
import re
import struct
from dataclasses import dataclass

from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from acslam.errors import CodecError, MessageError

DISTROS = ("humble", "jazzy", "kilted", "rolling")
DEFAULT_DISTRO = "jazzy"
"""The current LTS, and the release line whose rmw_zenoh sources the formats cite."""

_STORES = {
    "humble": Stores.ROS2_HUMBLE,
    "jazzy": Stores.ROS2_JAZZY,
    "kilted": Stores.ROS2_KILTED,
    # Rolling gets the newest store rosbags has, Lyrical (the release branched from it);
    # rosbags' Stores.LATEST is an alias of Kilted.
    "rolling": Stores.ROS2_LYRICAL,
}

ENTITY_KINDS = ("MP", "MS", "SS", "SC")
"""Liveliness entity kinds besides nodes (NN): publisher, subscription, service, client."""

ATTACHMENT_FORMATS = ("positional", "legacy")

GID_SIZE_BYTES = 16

_TOKEN_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
_FQ_NAME = re.compile(rf"/{_TOKEN_NAME}(/{_TOKEN_NAME})*")
_NODE_NAME = re.compile(_TOKEN_NAME)
_ZID = re.compile(r"[0-9a-f]{1,32}")

# rmw_zenoh's QoS defaults (qos.cpp at 0.2.10): a field equal to one is written empty.
_DEFAULT_DEPTH = 42
_BEST_EFFORT = 2  # rmw_qos_reliability_policy_e
_TRANSIENT_LOCAL = 1  # rmw_qos_durability_policy_e

_INT64 = struct.Struct("<q")
_SEQ_STAMP = struct.Struct("<qq")  # the positional format's sequence number and timestamp
_POSITIONAL_SIZE_BYTES = _SEQ_STAMP.size + 1 + GID_SIZE_BYTES
_LEGACY_KEYS = ("sequence_number", "source_timestamp", "source_gid")

_CDR_REPRESENTATIONS = (b"\x00\x01", b"\x00\x00")  # CDR_LE, CDR_BE


@functools.cache
def typestore(distro: str) -> Typestore:
    """The rosbags message types of ``distro``; built once per process (it takes ~0.1 s)."""
    if distro not in _STORES:
        raise ValueError(f"unknown ROS 2 distro {distro!r}; expected one of {DISTROS}")
    return get_typestore(_STORES[distro])


def _check_msgtype(msgtype: str, distro: str) -> None:
    if msgtype not in typestore(distro).types:
        raise ValueError(f"unknown message type {msgtype!r} for ROS 2 {distro}")


def dds_type_name(msgtype: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs::msg::dds_::String_``, the name rmw_zenoh puts
    in keys and tokens (the Fast-DDS type support's name)."""
    parts = msgtype.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"message type {msgtype!r} must look like 'pkg/msg/Name'")
    package, kind, name = parts
    return f"{package}::{kind}::dds_::{name}_"


@functools.cache
def type_hash(msgtype: str, distro: str) -> str:
    """The type hash chunk of keys and tokens: ``RIHS01_<sha256 hex>``; Humble's rmw_zenoh
    has no type hashes and writes ``TypeHashNotSupported`` instead. Cached: hashing a type
    description takes ~50 us."""
    _check_msgtype(msgtype, distro)
    if distro == "humble":
        return "TypeHashNotSupported"
    return typestore(distro).hash_rihs01(msgtype)


def _fq_name(what: str, name: str) -> str:
    if not _FQ_NAME.fullmatch(name):
        raise ValueError(f"{what} {name!r} must be a fully qualified ROS name like '/robot1/scan'")
    return name


def _namespace(namespace: str) -> str:
    return namespace if namespace == "/" else _fq_name("namespace", namespace)


def _domain(domain_id: int) -> str:
    if not isinstance(domain_id, int) or domain_id < 0:
        raise ValueError(f"domain id must be a non-negative integer, got {domain_id!r}")
    return str(domain_id)


def topic_key(domain_id: int, topic: str, msgtype: str, distro: str) -> str:
    """The data key expression rmw_zenoh publishes ``topic`` on.

    As ``strip_slashes`` does, the leading slash is removed (a valid fully qualified name
    has no trailing one) and inner slashes are kept: ``/robot1/chatter`` ->
    ``0/robot1/chatter/std_msgs::msg::dds_::String_/RIHS01_...``. Names are validated, so
    no wildcard or empty chunk can reach a key.
    """
    stripped = _fq_name("topic", topic)[1:]
    return f"{_domain(domain_id)}/{stripped}/{dds_type_name(msgtype)}/{type_hash(msgtype, distro)}"


def bridge_key(topic: str, namespace: str = "/") -> str:
    """The key zenoh-bridge-ros2dds routes ``topic`` on: the name without its leading slash,
    prefixed by the bridge's ``namespace`` setting (``/`` = none, the bridge's default)."""
    stripped = _fq_name("topic", topic)[1:]
    prefix = _namespace(namespace)[1:]
    return f"{prefix}/{stripped}" if prefix else stripped


def mangle(name: str) -> str:
    """Token chunks cannot contain '/', so rmw_zenoh writes every '/' as '%'."""
    return name.replace("/", "%")


@dataclass(frozen=True)
class Qos:
    """The QoS that a liveliness token advertises (keep-last history).

    The rclcpp default is reliable, volatile, depth 10; nav2's latched ``/map`` is
    reliable, transient local, depth 1.
    """

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10

    def __post_init__(self) -> None:
        if not isinstance(self.depth, int) or self.depth < 0:
            raise ValueError(f"Qos.depth must be a non-negative integer, got {self.depth!r}")

    def keyexpr(self) -> str:
        """rmw_zenoh's ``R:D:H,depth:DLs,DLns:LSs,LSns:LV,LVs,LVns`` with every field that
        equals rmw_zenoh's default left empty (deadline, lifespan and liveliness are always
        the defaults here; depth 0 means the default depth, 42)."""
        reliability = "" if self.reliable else str(_BEST_EFFORT)
        durability = str(_TRANSIENT_LOCAL) if self.transient_local else ""
        depth = "" if self.depth in (0, _DEFAULT_DEPTH) else str(self.depth)
        return f"{reliability}:{durability}:,{depth}:,:,:,,"


def _token(
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: str,
    enclave: str,
    namespace: str,
    node_name: str,
    *topic_chunks: str,
) -> str:
    """``@ros2_lv/<domain>/<zid>/<nid>/<id>/<kind>/<enclave>/<namespace>/<name>[/...]``
    with '/' mangled in the name chunks (``Entity`` ctor)."""
    if not _ZID.fullmatch(zid):
        raise ValueError(f"zid {zid!r} must be a Zenoh id in lowercase hex")
    for what, value in (("node id", node_id), ("entity id", entity_id)):
        if not isinstance(value, int) or value < 0:
            raise ValueError(f"{what} must be a non-negative integer, got {value!r}")
    if not _NODE_NAME.fullmatch(node_name):
        raise ValueError(f"node name {node_name!r} must be a ROS name token like 'acslam'")
    return "/".join(
        (
            "@ros2_lv",
            _domain(domain_id),
            zid,
            str(node_id),
            str(entity_id),
            kind,
            mangle(_namespace(enclave)),
            mangle(_namespace(namespace)),
            node_name,
            *topic_chunks,
        )
    )


def node_token(
    domain_id: int, zid: str, node_id: int, namespace: str, node_name: str, enclave: str = "/"
) -> str:
    """The liveliness token of a node, ``.../<nid>/<nid>/NN/<enclave>/<namespace>/<name>``
    (a node is its own entity)."""
    return _token(domain_id, zid, node_id, node_id, "NN", enclave, namespace, node_name)


def entity_token(
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: str,
    namespace: str,
    node_name: str,
    topic: str,
    msgtype: str,
    distro: str,
    qos: Qos,
    enclave: str = "/",
) -> str:
    """The liveliness token of a publisher (MP), subscription (MS), service (SS) or client
    (SC): the node's chunks, then the mangled topic (leading slash kept), DDS type name,
    type hash and QoS string, with no trailing slash."""
    if kind not in ENTITY_KINDS:
        raise ValueError(f"entity kind {kind!r} must be one of {ENTITY_KINDS}")
    return _token(
        domain_id,
        zid,
        node_id,
        entity_id,
        kind,
        enclave,
        namespace,
        node_name,
        mangle(_fq_name("topic", topic)),
        dds_type_name(msgtype),
        type_hash(msgtype, distro),
        qos.keyexpr(),
    )


def gid_of(token: str) -> bytes:
    """A stable 16-byte GID for the entity whose liveliness token is ``token``.

    rmw_zenoh takes XXH3-128 of the token (``liveliness_utils.cpp`` at 0.2.10, the
    ``Entity`` ctor); here it is BLAKE2b-128 (hashlib, no extra dependency). rmw_zenoh
    never recomputes a GID from a token to check it: peers only compare the GIDs in
    attachments with each other, so any stable 16 bytes per entity work.
    """
    return hashlib.blake2b(token.encode(), digest_size=GID_SIZE_BYTES).digest()


@dataclass(frozen=True)
class Attachment:
    """The metadata rmw_zenoh attaches to every sample, query and reply.

    ``sequence_number`` counts a publisher's puts from 1; ``source_timestamp_ns`` is the
    system clock at publication (ns since the UNIX epoch); ``gid`` (16 bytes) names the
    publisher (or, on a service reply, the requesting client).
    """

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def __post_init__(self) -> None:
        for name in ("sequence_number", "source_timestamp_ns"):
            value = getattr(self, name)
            if not isinstance(value, int) or not -(2**63) <= value < 2**63:
                raise MessageError(f"Attachment.{name}: must be an int64, got {value!r}")
        if not isinstance(self.gid, bytes | bytearray) or len(self.gid) != GID_SIZE_BYTES:
            raise MessageError(f"Attachment.gid: must be {GID_SIZE_BYTES} bytes, got {self.gid!r}")
        object.__setattr__(self, "gid", bytes(self.gid))


def _z_string(text: str) -> bytes:
    """A zenoh-ext serialized string: LEB128 length (one byte below 128), then UTF-8."""
    return bytes((len(text),)) + text.encode()


def encode_attachment(attachment: Attachment, format: str = "positional") -> bytes:
    """The attachment bytes, in the zenoh-ext serialization rmw_zenoh uses.

    ``positional`` (rmw_zenoh >= 0.2.4 / 0.1.2, all of Kilted): int64 LE sequence number,
    int64 LE timestamp, LEB128 16 and the 16 gid bytes (33 bytes). ``legacy`` (Jazzy
    0.2.0-0.2.3, Humble 0.1.0-0.1.1): the same values, each after its key string (77 bytes).
    """
    seq = _INT64.pack(attachment.sequence_number)
    stamp = _INT64.pack(attachment.source_timestamp_ns)
    gid = bytes((GID_SIZE_BYTES,)) + attachment.gid  # LEB128 element count, then the bytes
    if format == "positional":
        return seq + stamp + gid
    if format == "legacy":
        seq_key, stamp_key, gid_key = (_z_string(key) for key in _LEGACY_KEYS)
        return seq_key + seq + stamp_key + stamp + gid_key + gid
    raise ValueError(f"attachment format {format!r} must be one of {ATTACHMENT_FORMATS}")


def _read_varint(data: bytes, pos: int, what: str) -> tuple[int, int]:
    """A LEB128 unsigned integer at ``pos``; returns (value, position after it)."""
    value = 0
    for shift in range(0, 63, 7):
        if pos >= len(data):
            raise CodecError(f"attachment: truncated in the length of {what} (byte {pos})")
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, pos
    raise CodecError(f"attachment: the length of {what} is not a valid LEB128 number")


def _read_gid(data: bytes, pos: int) -> tuple[bytes, int]:
    count, pos = _read_varint(data, pos, "the gid")
    if count != GID_SIZE_BYTES:
        raise CodecError(f"attachment: the gid has {count} bytes, expected {GID_SIZE_BYTES}")
    gid = data[pos : pos + count]
    if len(gid) != count:
        raise CodecError(f"attachment: truncated in the gid ({len(gid)} of {count} bytes)")
    return gid, pos + count


def _decode_legacy(data: bytes) -> Attachment:
    values: list[int] = []
    pos = 0
    for key in _LEGACY_KEYS:
        length, start = _read_varint(data, pos, f"key {key!r}")
        found = data[start : start + length]
        if len(found) < length:
            raise CodecError(f"legacy attachment: truncated in key {key!r} (byte {pos})")
        if found != key.encode():
            raise CodecError(
                f"legacy attachment: expected key {key!r} at byte {pos}, found {found!r}"
                " (the keys must come in the order sequence_number, source_timestamp,"
                " source_gid)"
            )
        pos = start + length
        if key == "source_gid":
            gid, pos = _read_gid(data, pos)
        else:
            if pos + _INT64.size > len(data):
                raise CodecError(f"legacy attachment: truncated in the value of {key!r}")
            values.append(_INT64.unpack_from(data, pos)[0])
            pos += _INT64.size
    if pos != len(data):
        raise CodecError(f"legacy attachment: {len(data) - pos} unexpected bytes after the gid")
    return Attachment(values[0], values[1], gid)


def decode_attachment(data: bytes) -> Attachment:
    """Parse an attachment in either format: 33 bytes with a gid length of 16 at byte 16 is
    positional, one that opens with a key string is legacy."""
    data = bytes(data)
    is_positional = len(data) == _POSITIONAL_SIZE_BYTES and data[_SEQ_STAMP.size] == GID_SIZE_BYTES
    if not is_positional and any(data.startswith(_z_string(key)) for key in _LEGACY_KEYS):
        return _decode_legacy(data)
    if len(data) <= _SEQ_STAMP.size:
        raise CodecError(
            f"attachment of {len(data)} bytes is too short: the positional format has"
            f" {_POSITIONAL_SIZE_BYTES} bytes and the legacy one opens with 'sequence_number'"
        )
    seq, stamp = _SEQ_STAMP.unpack_from(data)
    gid, pos = _read_gid(data, _SEQ_STAMP.size)
    if pos != len(data):
        raise CodecError(
            f"attachment of {len(data)} bytes: the positional format has"
            f" {_POSITIONAL_SIZE_BYTES} bytes"
        )
    return Attachment(seq, stamp, gid)


def encode_cdr(message: object, msgtype: str, distro: str) -> bytes:
    """Little-endian CDR with its ``00 01 00 00`` header, as Fast-CDR writes it."""
    _check_msgtype(msgtype, distro)
    if getattr(message, "__msgtype__", None) != msgtype:
        raise TypeError(f"message {type(message).__name__} is not a {msgtype}")
    return bytes(typestore(distro).serialize_cdr(message, msgtype, little_endian=True))


def decode_cdr(payload: bytes | memoryview, msgtype: str, distro: str) -> object:
    """The rosbags message object in a CDR payload.

    The header must be plain CDR (``00 01`` little- or ``00 00`` big-endian); its options
    bytes may carry the 0-3 padding count that Cyclone DDS writes (via
    zenoh-bridge-ros2dds). rosbags accepts at most 3 trailing padding bytes. Primitive
    arrays of the result are views into ``payload``.
    """
    _check_msgtype(msgtype, distro)
    header = bytes(payload[:4])
    if len(header) < 4:
        raise CodecError(f"{msgtype}: CDR payload of {len(payload)} bytes has no 4-byte header")
    if header[:2] not in _CDR_REPRESENTATIONS or header[2] != 0 or header[3] > 3:
        raise CodecError(
            f"{msgtype}: CDR header {header.hex(' ')} is not plain CDR"
            " (00 01 00 00 little-endian or 00 00 00 00 big-endian)"
        )
    try:
        return typestore(distro).deserialize_cdr(payload, msgtype)
    except SerdeError as exc:
        raise CodecError(f"{msgtype}: CDR payload does not decode: {exc}") from None
