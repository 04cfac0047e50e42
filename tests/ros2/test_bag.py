"""Bags without ROS: the public fixtures of ../shared read (ROS 1, rosbag2 in MCAP and
sqlite3 storage), written bags read back, and damaged files fail with one line."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader

from acslam.cli import main
from acslam.errors import DataError
from acslam.messages import LidarScan
from acslam.ros2 import convert
from acslam.ros2.bag import BagReader, BagWriter, MemoryBag

SAMPLES = "datasets/rosbag_samples"


def test_ros1_laser_scan_bag(shared_dataset: Callable[[str], Path]) -> None:
    """scan_tools_demo.bag (PROVENANCE.md): 360 LaserScans of 681 beams, frame laser."""
    path = shared_dataset(f"{SAMPLES}/scan_tools_demo.bag")
    with BagReader(path) as bag:
        assert bag.topics == {"/scan": "sensor_msgs/msg/LaserScan"}
        assert bag.counts == {"/scan": 360}
        scans = [item.message for item in bag.messages()]
    assert len(scans) == 360
    assert {len(scan.ranges) for scan in scans} == {681}
    assert {convert.frame_id(scan) for scan in scans} == {"laser"}
    stamps = np.array([convert.header_stamp_s(scan) for scan in scans])
    assert np.all(np.diff(stamps) > 0) and stamps[-1] - stamps[0] == pytest.approx(
        35.8159, abs=1e-3
    )


@pytest.mark.parametrize(
    "relpath",
    [
        "rosbag2_talker_mcap/talker.mcap",
        "rosbag2_talker_sqlite3/talker.db3",
        "rosbag2_talker_mcap",
        "rosbag2_talker_sqlite3",
    ],
)
def test_rosbag2_talker_reads_from_either_storage(
    shared_dataset: Callable[[str], Path], relpath: str
) -> None:
    """The talker recording of rosbag2's own tests, as a storage file or its folder (whose
    metadata QoS differs from the storage's): 10 std_msgs/String, and rosout's Log
    messages, which the sqlite3 file's placeholder definitions could not decode."""
    with BagReader(shared_dataset(f"{SAMPLES}/{relpath}")) as bag:
        assert bag.topics == {
            "/rosout": "rcl_interfaces/msg/Log",
            "/parameter_events": "rcl_interfaces/msg/ParameterEvent",
            "/topic": "std_msgs/msg/String",
        }
        assert bag.counts["/topic"] == 10
        strings = [item.message.data for item in bag.messages(["/topic"])]
        logs = [item.message for item in bag.messages(["/rosout"])]
    assert strings == [f"Hello, world! {n}" for n in range(10)]
    assert len(logs) == 10 and logs[0].msg == "Publishing: 'Hello, world! 0'"


def test_a_written_bag_reads_back_with_its_latched_topics(tmp_path: Path) -> None:
    path = tmp_path / "out" / "written.mcap"
    ranges = np.array([1.0, np.inf, 0.0, 2.5])
    scan = LidarScan(0, 12.25, np.linspace(-1.0, 1.0, 4), ranges, 8.0)
    with BagWriter(path) as bag:
        bag.write("/scan", convert.laser_scan_msg(scan, 12.25, "laser", 0.1), 12.25)
        mount = convert.tf_message([("base_link", "laser", 0.0, [0.1, 0.0, 0.0])])
        bag.write("/tf_static", mount, 0.0, latched=True)
    assert sorted(p.name for p in path.parent.iterdir()) == ["written.mcap"]
    with BagReader(path) as bag:
        items = {item.topic: item for item in bag.messages()}
    assert items["/scan"].log_time_ns == 12_250_000_000
    decoded = convert.laser_scan(items["/scan"].message, 0, 12.25)
    np.testing.assert_array_equal(decoded.ranges, ranges)
    assert convert.tf_transforms(items["/tf_static"].message)[0][:2] == ("base_link", "laser")
    with Reader(path) as raw:
        durability = {
            c.topic: c.ext.offered_qos_profiles[0].durability
            if c.ext.offered_qos_profiles
            else None
            for c in raw.connections
        }
    assert durability == {"/scan": None, "/tf_static": QosDurability.TRANSIENT_LOCAL}


def test_a_bag_in_memory_reads_as_its_file(tmp_path: Path) -> None:
    """The same writes into a file and into memory read back as the same messages in the
    same order: by log time, equal times in the order written, whatever the topic."""
    path = tmp_path / "same.mcap"
    scans = [
        LidarScan(0, stamp_s, np.linspace(-np.pi / 2, np.pi / 2, 5), np.full(5, 1.01 + k), 8.0)
        for k, stamp_s in enumerate([2.0, 1.0, 1.0, 3.5])
    ]
    with BagWriter(path) as file_bag:
        memory_bag = MemoryBag(path)
        for bag in (file_bag, memory_bag):
            bag.write("/tf_static", convert.tf_message([("b", "l", 3.0, [0.1, 0, 0])]), 3.0, True)
            for k, scan in enumerate(scans):
                bag.write("/scan", convert.laser_scan_msg(scan, scan.stamp, "l", 0.0), scan.stamp)
                odometry = convert.odometry_msg(scan.stamp, [k, 0, 0], 0, 0, "o", "b")
                bag.write("/odom", odometry, scan.stamp)
    with BagReader(path) as file_bag:
        assert (file_bag.topics, file_bag.counts) == (memory_bag.topics, memory_bag.counts)
        from_file = list(file_bag.messages(["/scan", "/odom", "/tf_static"]))
    from_memory = list(memory_bag.messages())
    order = [(item.topic, item.log_time_ns) for item in from_memory]
    assert order == [(item.topic, item.log_time_ns) for item in from_file]
    assert [t for t, _ in order] == ["/scan", "/odom"] * 3 + ["/tf_static", "/scan", "/odom"]
    assert [stamp for _, stamp in order] == [10**9] * 4 + [2 * 10**9] * 2 + [3 * 10**9] + [
        3_500_000_000
    ] * 2
    for memory_item, file_item in zip(from_memory, from_file, strict=True):
        memory, file = memory_item.message, file_item.message
        if memory_item.topic == "/scan":
            a, b = convert.laser_scan(memory, 0, 0.0), convert.laser_scan(file, 0, 0.0)
            assert np.array_equal(a.angles, b.angles) and np.array_equal(a.ranges, b.ranges)
            assert a.range_max_m == b.range_max_m
        elif memory_item.topic == "/odom":
            a_odom, b_odom = convert.odometry_pose(memory), convert.odometry_pose(file)
            assert a_odom[0] == b_odom[0] and np.array_equal(a_odom[1], b_odom[1])
        else:
            (a_tf,), (b_tf,) = convert.tf_transforms(memory), convert.tf_transforms(file)
            assert a_tf[:3] == b_tf[:3] and np.array_equal(a_tf[3], b_tf[3])
    assert [item.topic for item in memory_bag.messages(["/odom"])] == ["/odom"] * 4


def _damaged(tmp_path: Path) -> list[Path]:
    rng = np.random.default_rng(7)
    whole = tmp_path / "whole.mcap"
    with BagWriter(whole) as bag:
        for k in range(50):
            scan = LidarScan(0, k * 0.1, np.linspace(-1.0, 1.0, 100), np.full(100, 2.0), 8.0)
            bag.write("/scan", convert.laser_scan_msg(scan, k * 0.1, "laser", 0.0), k * 0.1)
    files = {
        "random.mcap": rng.bytes(4096),
        "truncated.mcap": whole.read_bytes()[: whole.stat().st_size // 2],
        "random.db3": rng.bytes(4096),
        "random.bag": rng.bytes(4096),
    }
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    return [tmp_path / name for name in files]


def test_a_damaged_or_missing_bag_is_one_data_error_naming_the_file(tmp_path: Path) -> None:
    for path in [*_damaged(tmp_path), tmp_path / "missing.mcap", tmp_path / "notes.txt"]:
        with pytest.raises(DataError) as info, BagReader(path) as bag:
            list(bag.messages())
        assert info.value.path == str(path)
        assert "\n" not in str(info.value)


def test_cli_on_a_truncated_bag_prints_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    truncated = _damaged(tmp_path)[1]
    argv = ["acslam", "slam", "rosbag", str(truncated), "--out", str(tmp_path / "out")]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as stopped:
        main()
    error = capsys.readouterr().err
    assert stopped.value.code == 1
    assert error.startswith(f"acslam: error: {truncated}: not a readable bag")
    assert "Traceback" not in error and error.count("\n") == 1
