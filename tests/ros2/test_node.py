"""What a node puts on the wire: rmw_zenoh's key and attachment, or the DDS bridge's bare
key, and the tokens that make it visible to ``ros2 node list``."""

from __future__ import annotations

import time

import pytest

from acslam.distributed.launch import free_port
from acslam.ros2 import convert, wire
from acslam.ros2.node import Ros2Node, Ros2Options, open_ros2_session


@pytest.fixture
def sessions():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_ros2_session(listen=endpoint)
    client = open_ros2_session(connect=[endpoint], timeout_s=10)
    yield router, client
    client.close()
    router.close()


def _until(condition, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert condition()


@pytest.mark.parametrize("bridge", [False, True])
def test_a_twist_crosses_with_the_format_of_its_mode(sessions, bridge: bool) -> None:
    router, client = sessions
    options = Ros2Options(distro="jazzy", bridge=bridge)
    raw, decoded = [], []
    key = (
        "robot1/cmd_vel"
        if bridge
        else wire.topic_key(0, "/robot1/cmd_vel", "geometry_msgs/msg/Twist", "jazzy")
    )
    tap = client.declare_subscriber(key, lambda s: raw.append(s))
    receiver = Ros2Node(client, "listener", "/", options)
    receiver.subscribe("/robot1/cmd_vel", "geometry_msgs/msg/Twist", decoded.append)
    sender = Ros2Node(router, "talker", "/", options)
    publisher = sender.publisher("/robot1/cmd_vel", "geometry_msgs/msg/Twist")
    time.sleep(0.3)
    publisher.put(convert.twist_msg(0.2, -0.5, "jazzy"))
    _until(lambda: raw and decoded)
    assert convert.twist_command(decoded[0]) == (0.2, -0.5)
    payload = raw[0].payload.to_bytes()
    assert payload[:4] == b"\x00\x01\x00\x00" and len(payload) == 4 + 6 * 8
    if bridge:
        assert raw[0].attachment is None
    else:
        attachment = wire.decode_attachment(raw[0].attachment.to_bytes())
        assert attachment.sequence_number == 1 and len(raw[0].attachment.to_bytes()) == 33
        assert attachment.gid == publisher.gid
        tokens = [str(r.ok.key_expr) for r in client.liveliness().get("@ros2_lv/0/**")]
        assert any(t.endswith("/NN/%/%/talker") for t in tokens)
        assert any("/MP/%/%/talker/%robot1%cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_"
                   in t and t.endswith("/::,10:,:,:,,") for t in tokens)  # fmt: skip
    for node in (sender, receiver):
        node.close()
    tap.undeclare()
    if not bridge:  # closing a node takes its tokens off the graph
        _until(lambda: not [r for r in client.liveliness().get("@ros2_lv/0/**")])
