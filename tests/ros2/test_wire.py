"""The rmw_zenoh wire format against the strings and bytes of rmw_zenoh's design doc, the
zenoh-ext serializer and a real rosbag2 recording."""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

import pytest
from rosbags.rosbag2 import Reader
from zenoh.ext import Int64, z_serialize

from acslam.errors import CodecError, MessageError
from acslam.ros2 import wire

# rmw_zenoh docs/design.md (Jazzy 0.2.10, 70d155975adf9b2a1a920c02b247d9f2b6e6467f).
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
GRID_HASH = "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7"
STRING_DDS = "std_msgs::msg::dds_::String_"
LISTENER_ZID = "aac3178e146ba6f1fc6e6a4085e77f21"
TALKER_ZID = "8b20917502ee955ac4476e0266340d5c"

# rmw_zenoh's attachment of seq 1, timestamp 0x0102030405060708, gid 00..0f, worked by hand.
SEQ, STAMP_NS, GID = 1, 0x0102030405060708, bytes(range(16))
POSITIONAL_HEX = "0100000000000000 0807060504030201 10 000102030405060708090a0b0c0d0e0f"
LEGACY_HEX = (
    "0f 73657175656e63655f6e756d626572 0100000000000000"  # 'sequence_number', seq
    " 10 736f757263655f74696d657374616d70 0807060504030201"  # 'source_timestamp', stamp
    " 0a 736f757263655f676964 10 000102030405060708090a0b0c0d0e0f"  # 'source_gid', gid
)

TALKER_MCAP = "datasets/rosbag_samples/rosbag2_talker_mcap/talker.mcap"
HELLO_CDR = bytes.fromhex("00010000 06000000 48656c6c6f00")  # String('Hello'), LE


def test_typestore_is_cached_per_distro() -> None:
    assert wire.typestore("jazzy") is wire.typestore("jazzy")
    assert "visualization_msgs/msg/MarkerArray" in wire.typestore("rolling").types
    with pytest.raises(ValueError, match="iron"):
        wire.typestore("iron")


@pytest.mark.parametrize("distro", ["jazzy", "kilted", "rolling"])
def test_type_hash_is_the_design_docs(distro: str) -> None:
    assert wire.type_hash("std_msgs/msg/String", distro) == STRING_HASH
    assert wire.type_hash("nav_msgs/msg/OccupancyGrid", distro) == GRID_HASH


def test_humble_has_no_type_hash() -> None:
    assert wire.type_hash("std_msgs/msg/String", "humble") == "TypeHashNotSupported"
    with pytest.raises(ValueError, match="unknown message type"):
        wire.type_hash("std_msgs/msg/Nope", "humble")


def test_dds_type_name() -> None:
    assert wire.dds_type_name("std_msgs/msg/String") == STRING_DDS
    assert wire.dds_type_name("nav_msgs/msg/OccupancyGrid") == "nav_msgs::msg::dds_::OccupancyGrid_"
    with pytest.raises(ValueError):
        wire.dds_type_name("String")


def test_topic_keys_are_the_design_docs() -> None:
    key = wire.topic_key(0, "/chatter", "std_msgs/msg/String", "jazzy")
    assert key == f"0/chatter/{STRING_DDS}/{STRING_HASH}"
    key = wire.topic_key(0, "/robot1/chatter", "std_msgs/msg/String", "jazzy")
    assert key == f"0/robot1/chatter/{STRING_DDS}/{STRING_HASH}"
    key = wire.topic_key(7, "/chatter", "std_msgs/msg/String", "humble")
    assert key == f"7/chatter/{STRING_DDS}/TypeHashNotSupported"


@pytest.mark.parametrize("topic", ["chatter", "/", "/a//b", "/robot1/*", "/robot1/**", "/1scan"])
def test_topic_keys_refuse_names_that_are_not_fully_qualified(topic: str) -> None:
    with pytest.raises(ValueError, match="fully qualified"):
        wire.topic_key(0, topic, "std_msgs/msg/String", "jazzy")


def test_topic_key_refuses_a_negative_domain() -> None:
    with pytest.raises(ValueError, match="domain"):
        wire.topic_key(-1, "/chatter", "std_msgs/msg/String", "jazzy")


def test_bridge_keys() -> None:
    assert wire.bridge_key("/robot1/scan") == "robot1/scan"
    assert wire.bridge_key("/scan", "/robot1") == "robot1/scan"
    assert wire.bridge_key("/map", "/fleet/bot2") == "fleet/bot2/map"
    with pytest.raises(ValueError, match="namespace"):
        wire.bridge_key("/scan", "robot1")


def test_mangle() -> None:
    assert wire.mangle("/") == "%"
    assert wire.mangle("/robot1/chatter") == "%robot1%chatter"


@pytest.mark.parametrize(
    ("qos", "keyexpr"),
    [
        (wire.Qos(), "::,10:,:,:,,"),  # rclcpp's default
        (wire.Qos(depth=7), "::,7:,:,:,,"),  # the design doc's talker
        (wire.Qos(transient_local=True, depth=1), ":1:,1:,:,:,,"),  # nav2 /map
        (wire.Qos(reliable=False, depth=5), "2::,5:,:,:,,"),  # sensor data
        (wire.Qos(depth=42), "::,:,:,:,,"),  # rmw_zenoh's default depth
        (wire.Qos(depth=0), "::,:,:,:,,"),  # depth 0 = the default depth
    ],
)
def test_qos_keyexpr(qos: wire.Qos, keyexpr: str) -> None:
    assert qos.keyexpr() == keyexpr


def test_qos_refuses_a_negative_depth() -> None:
    with pytest.raises(ValueError, match="depth"):
        wire.Qos(depth=-1)


def test_tokens_are_the_design_docs() -> None:
    node = wire.node_token(0, LISTENER_ZID, 0, "/", "listener")
    assert node == f"@ros2_lv/0/{LISTENER_ZID}/0/0/NN/%/%/listener"
    subscription = wire.entity_token(
        0, LISTENER_ZID, 0, 10, "MS", "/", "listener", "/chatter", "std_msgs/msg/String",
        "jazzy", wire.Qos(depth=10),
    )  # fmt: skip
    assert subscription == (
        f"@ros2_lv/0/{LISTENER_ZID}/0/10/MS/%/%/listener/%chatter/{STRING_DDS}/{STRING_HASH}"
        "/::,10:,:,:,,"
    )
    publisher = wire.entity_token(
        0, TALKER_ZID, 0, 10, "MP", "/", "talker", "/chatter", "std_msgs/msg/String", "jazzy",
        wire.Qos(depth=7),
    )  # fmt: skip
    assert publisher == (
        f"@ros2_lv/0/{TALKER_ZID}/0/10/MP/%/%/talker/%chatter/{STRING_DDS}/{STRING_HASH}"
        "/::,7:,:,:,,"
    )


def test_map_publisher_token_in_a_namespace() -> None:
    token = wire.entity_token(
        3, TALKER_ZID, 4, 5, "MP", "/robot1", "map_server", "/robot1/map",
        "nav_msgs/msg/OccupancyGrid", "kilted", wire.Qos(transient_local=True, depth=1),
    )  # fmt: skip
    assert token == (
        f"@ros2_lv/3/{TALKER_ZID}/4/5/MP/%/%robot1/map_server/%robot1%map"
        f"/nav_msgs::msg::dds_::OccupancyGrid_/{GRID_HASH}/:1:,1:,:,:,,"
    )
    assert not token.endswith("/")


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"kind": "XX"}, "entity kind"),
        ({"zid": "AAC3"}, "zid"),
        ({"node_name": "my/node"}, "node name"),
        ({"namespace": "robot1"}, "namespace"),
        ({"entity_id": -1}, "entity id"),
    ],
)
def test_entity_token_refuses_invalid_parts(change: dict, problem: str) -> None:
    arguments = {
        "domain_id": 0, "zid": LISTENER_ZID, "node_id": 0, "entity_id": 1, "kind": "MS",
        "namespace": "/", "node_name": "listener", "topic": "/chatter",
        "msgtype": "std_msgs/msg/String", "distro": "jazzy", "qos": wire.Qos(),
    }  # fmt: skip
    with pytest.raises(ValueError, match=problem):
        wire.entity_token(**(arguments | change))


def test_gid_is_stable_and_distinct_per_token() -> None:
    first = wire.node_token(0, LISTENER_ZID, 0, "/", "listener")
    second = wire.node_token(0, LISTENER_ZID, 1, "/", "listener")
    assert len(wire.gid_of(first)) == 16
    assert wire.gid_of(first) == wire.gid_of(first)
    assert wire.gid_of(first) != wire.gid_of(second)


def test_attachments_are_the_worked_examples() -> None:
    attachment = wire.Attachment(SEQ, STAMP_NS, GID)
    assert wire.encode_attachment(attachment, "positional") == bytes.fromhex(POSITIONAL_HEX)
    assert wire.encode_attachment(attachment, "legacy") == bytes.fromhex(LEGACY_HEX)
    assert len(bytes.fromhex(POSITIONAL_HEX)) == 33
    assert len(bytes.fromhex(LEGACY_HEX)) == 77


def _z_positional(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    return bytes(z_serialize((Int64(seq), Int64(stamp_ns), gid)))


def _z_legacy(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    return _z_fields(("sequence_number", seq), ("source_timestamp", stamp_ns), ("source_gid", gid))


def _z_fields(*fields: tuple[str, int | bytes]) -> bytes:
    """Key/value pairs as zenoh-ext serializes them (ints as int64)."""
    flat: list[object] = []
    for key, value in fields:
        flat += [key, Int64(value) if isinstance(value, int) else value]
    return bytes(z_serialize(tuple(flat)))


def test_attachments_match_zenoh_ext_and_round_trip() -> None:
    rng = random.Random(7)
    for _ in range(50):
        seq = rng.randrange(-(2**63), 2**63)
        stamp_ns = rng.randrange(-(2**63), 2**63)
        gid = rng.randbytes(16)
        attachment = wire.Attachment(seq, stamp_ns, gid)
        positional = wire.encode_attachment(attachment, "positional")
        legacy = wire.encode_attachment(attachment, "legacy")
        assert positional == _z_positional(seq, stamp_ns, gid)
        assert legacy == _z_legacy(seq, stamp_ns, gid)
        assert wire.decode_attachment(positional) == attachment
        assert wire.decode_attachment(legacy) == attachment


POSITIONAL = bytes.fromhex(POSITIONAL_HEX)
LEGACY = bytes.fromhex(LEGACY_HEX)


@pytest.mark.parametrize(
    ("data", "problem"),
    [
        (b"", "too short"),
        (POSITIONAL[:10], "too short"),
        (POSITIONAL[:32], "truncated in the gid"),
        (POSITIONAL + b"\x00", "33 bytes"),
        (_z_positional(SEQ, STAMP_NS, bytes(range(15))), "gid has 15 bytes"),
        (LEGACY[:-1], "truncated in the gid"),
        (LEGACY[:30], "truncated in key 'source_timestamp'"),
        (LEGACY[:45], "truncated in the value of 'source_timestamp'"),
        (LEGACY + b"\x00", "1 unexpected bytes"),
        (
            _z_fields(
                ("source_timestamp", STAMP_NS), ("sequence_number", SEQ), ("source_gid", GID)
            ),
            "expected key 'sequence_number'",
        ),
        (_z_legacy(SEQ, STAMP_NS, bytes(range(15))), "gid has 15 bytes"),
    ],
)
def test_malformed_attachments_raise(data: bytes, problem: str) -> None:
    with pytest.raises(CodecError, match=problem):
        wire.decode_attachment(data)


def test_attachment_fields_are_validated() -> None:
    with pytest.raises(MessageError, match="gid"):
        wire.Attachment(SEQ, STAMP_NS, bytes(15))
    with pytest.raises(MessageError, match="sequence_number"):
        wire.Attachment(2**63, STAMP_NS, GID)
    with pytest.raises(ValueError, match="format"):
        wire.encode_attachment(wire.Attachment(SEQ, STAMP_NS, GID), "json")


def _first_talker_message(shared_dataset: Callable[[str], Path]) -> bytes:
    # The .mcap file, not its folder: the folder's metadata.yaml QoS differs from the one
    # stored in the file, and rosbags then yields no message at all.
    with Reader(shared_dataset(TALKER_MCAP)) as reader:
        connections = [c for c in reader.connections if c.topic == "/topic"]
        _, _, raw = next(iter(reader.messages(connections=connections)))
    return bytes(raw)


@pytest.mark.parametrize("distro", wire.DISTROS)
def test_cdr_of_a_real_talker_round_trips(
    shared_dataset: Callable[[str], Path], distro: str
) -> None:
    raw = _first_talker_message(shared_dataset)
    message = wire.decode_cdr(raw, "std_msgs/msg/String", distro)
    assert message.data == "Hello, world! 0"
    assert wire.encode_cdr(message, "std_msgs/msg/String", distro) == raw


def test_cdr_headers() -> None:
    string = wire.typestore("jazzy").types["std_msgs/msg/String"]
    assert wire.encode_cdr(string(data="Hello"), "std_msgs/msg/String", "jazzy") == HELLO_CDR
    big_endian = bytes.fromhex("00000000 00000006 48656c6c6f00")
    assert wire.decode_cdr(big_endian, "std_msgs/msg/String", "jazzy").data == "Hello"
    # Cyclone DDS writes the padding count into the options (via zenoh-bridge-ros2dds).
    padded = bytes.fromhex("00010002 06000000 48656c6c6f00 0000")
    assert wire.decode_cdr(padded, "std_msgs/msg/String", "jazzy").data == "Hello"


def _garbage() -> list[bytes]:
    rng = random.Random(3)
    return [b"\x00\x01\x00\x00" + rng.randbytes(rng.randrange(1, 40)) for _ in range(20)]


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\x00\x01",
        b"\x00\x01\x00\x00",  # a header, no body
        b"\x00\x07\x00\x00" + HELLO_CDR[4:],  # XCDR2, not plain CDR
        b"\x01\x01\x00\x00" + HELLO_CDR[4:],
        b"\x00\x01\x01\x00" + HELLO_CDR[4:],
        b"\x00\x01\x00\x00\xff\xff\xff\xff",  # a string longer than the payload
        HELLO_CDR + b"junkjunk",
        b"Hello, world!",
    ],
)
def test_undecodable_cdr_raises(payload: bytes) -> None:
    with pytest.raises(CodecError, match="std_msgs/msg/String"):
        wire.decode_cdr(payload, "std_msgs/msg/String", "jazzy")


def test_random_garbage_never_escapes_as_another_error() -> None:
    decoded = 0
    for payload in _garbage():
        for msgtype in ("sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry"):
            try:
                wire.decode_cdr(payload, msgtype, "jazzy")
                decoded += 1
            except CodecError as error:
                assert msgtype in str(error)
    assert decoded < 5


def test_cdr_refuses_a_mismatched_or_unknown_type() -> None:
    string = wire.typestore("jazzy").types["std_msgs/msg/String"]
    with pytest.raises(TypeError, match="Twist"):
        wire.encode_cdr(string(data="x"), "geometry_msgs/msg/Twist", "jazzy")
    with pytest.raises(ValueError, match="unknown message type"):
        wire.decode_cdr(HELLO_CDR, "std_msgs/msg/Nope", "jazzy")
