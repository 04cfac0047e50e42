"""ROS message <-> acslam conversions: analytic cases, round trips through CDR, the ROS
conventions (REP 117 ranges, OccupancyGrid layout) and a real LaserScan."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag1 import Reader
from scipy.spatial.transform import Rotation

from acslam.errors import CodecError, MessageError
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from acslam.messages import LandmarkObservations, LidarScan
from acslam.ros2 import convert, wire

T = wire.typestore("jazzy").types
SCAN_BAG = "datasets/rosbag_samples/scan_tools_demo.bag"


def through_cdr(message: Any, distro: str = "jazzy") -> Any:
    """The message as a ROS node would receive it."""
    msgtype = message.__msgtype__
    return wire.decode_cdr(wire.encode_cdr(message, msgtype, distro), msgtype, distro)


def assert_same_values(built: Any, received: Any, where: str = "") -> None:
    """Every field of two messages equal, bit for bit (NaN equal to NaN)."""
    if dataclasses.is_dataclass(built):
        assert type(built).__name__ == type(received).__name__, where
        for field in dataclasses.fields(built):
            name = f"{where}.{field.name}"
            assert_same_values(getattr(built, field.name), getattr(received, field.name), name)
    elif isinstance(built, np.ndarray):
        assert built.dtype == received.dtype, where
        assert np.array_equal(built, received, equal_nan=built.dtype.kind == "f"), where
    elif isinstance(built, list):
        assert len(built) == len(received), where
        for k, (a, b) in enumerate(zip(built, received, strict=True)):
            assert_same_values(a, b, f"{where}[{k}]")
    else:
        assert built == received or (built != built and received != received), where


def quaternion(x: float, y: float, z: float, w: float) -> Any:
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def pose(x: float, y: float, q: Any) -> Any:
    position = T["geometry_msgs/msg/Point"](x=x, y=y, z=0.5)
    return T["geometry_msgs/msg/Pose"](position=position, orientation=q)


# ------------------------------------------------------------------------------ time


@pytest.mark.parametrize(
    ("stamp_s", "sec", "nanosec"),
    [
        (1.5, 1, 500_000_000),
        (-0.25, -1, 750_000_000),
        (2.9999999999, 3, 0),  # rounds up into the next second
        (0.0, 0, 0),
    ],
)
def test_ros_time(stamp_s: float, sec: int, nanosec: int) -> None:
    stamp = convert.ros_time(stamp_s)
    assert (stamp.sec, stamp.nanosec) == (sec, nanosec)


def test_ros_time_round_trips_to_the_nearest_ns() -> None:
    for stamp_s in (1_700_000_000.123456789, 12.000000001, 5e-10):
        assert abs(convert.time_s(convert.ros_time(stamp_s)) - stamp_s) <= 0.5e-9 + 1e-16 * stamp_s


def test_invalid_times_raise() -> None:
    with pytest.raises(MessageError):
        convert.ros_time(math.nan)
    with pytest.raises(MessageError, match="int32"):
        convert.ros_time(2.0**31)
    bad = T["builtin_interfaces/msg/Time"](sec=1, nanosec=1_000_000_000)
    with pytest.raises(CodecError, match="nanosec"):
        convert.time_s(bad)


# ------------------------------------------------------------------------------ poses


def test_yaw_of_a_planar_quaternion() -> None:
    q = quaternion(0.0, 0.0, math.sin(0.15), math.cos(0.15))
    assert convert.planar_pose(pose(1.0, -2.0, q)) == pytest.approx([1.0, -2.0, 0.3])


def test_yaw_of_tilted_quaternions_matches_scipy() -> None:
    rng = np.random.default_rng(5)
    for xyzw in Rotation.random(20, random_state=rng).as_quat():
        expected_yaw = Rotation.from_quat(xyzw).as_euler("ZYX")[0]
        yaw = convert.planar_pose(pose(0.0, 0.0, quaternion(*xyzw)))[2]
        assert math.remainder(yaw - expected_yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_pose_and_transform_round_trip() -> None:
    xytheta = np.array([3.0, -1.5, -2.5])
    assert convert.planar_pose(through_cdr(convert.pose_msg(xytheta))) == pytest.approx(xytheta)
    transform = through_cdr(convert.transform_msg(xytheta))
    assert convert.transform_xytheta(transform) == pytest.approx(xytheta)


@pytest.mark.parametrize(
    ("position", "q", "problem"),
    [
        ((math.nan, 0.0), (0.0, 0.0, 0.0, 1.0), r"Pose.position.x"),
        ((0.0, math.inf), (0.0, 0.0, 0.0, 1.0), r"Pose.position.y"),
        ((0.0, 0.0), (0.0, 0.0, 0.0, 0.5), "norm 0.5"),
        ((0.0, 0.0), (0.0, 0.0, 0.0, 0.0), "norm 0"),
        ((0.0, 0.0), (0.0, 0.0, math.nan, 1.0), "finite"),
    ],
)
def test_invalid_poses_raise(position: tuple, q: tuple, problem: str) -> None:
    with pytest.raises(CodecError, match=problem):
        convert.planar_pose(pose(*position, quaternion(*q)))


def test_a_decoder_refuses_another_message_type() -> None:
    with pytest.raises(CodecError, match="expected a geometry_msgs/msg/Pose"):
        convert.planar_pose(convert.transform_msg([0.0, 0.0, 0.0]))


# ------------------------------------------------------------------------------ LaserScan


def laser_scan_msg(ranges: list[float], **geometry: float) -> Any:
    fields = {
        "angle_min": -1.0, "angle_max": 1.0, "angle_increment": 0.5, "range_min": 0.1,
        "range_max": 30.0,
    } | geometry  # fmt: skip
    return T["sensor_msgs/msg/LaserScan"](
        header=T["std_msgs/msg/Header"](stamp=convert.ros_time(4.25), frame_id="laser"),
        time_increment=0.0,
        scan_time=0.1,
        ranges=np.array(ranges, dtype=np.float32),
        intensities=np.zeros(0, dtype=np.float32),
        **fields,
    )


def test_laser_scan_follows_rep_117() -> None:
    message = through_cdr(laser_scan_msg([1.0, math.inf, math.nan, 0.01, 50.0, -math.inf, -1.0]))
    scan = convert.laser_scan(message, 2, 7.0)
    assert scan.ranges.tolist() == [1.0, math.inf, 0.0, 0.0, math.inf, 0.0, 0.0]
    assert scan.angles == pytest.approx([-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0])
    assert (scan.robot_id, scan.stamp, scan.range_max_m) == (2, 7.0, 30.0)
    assert convert.header_stamp_s(message) == 4.25
    assert convert.frame_id(message) == "laser"


@pytest.mark.parametrize(
    ("geometry", "field"),
    [
        ({"angle_increment": 0.0}, "angle_increment"),
        ({"angle_increment": math.nan}, "angle_increment"),
        ({"angle_increment": 7.0}, "angle_increment"),
        ({"angle_min": math.inf}, "angle_min"),
        ({"range_max": 0.0}, "range_max"),
        ({"range_max": math.inf}, "range_max"),
        ({"range_min": math.nan}, "range_min"),
        ({"range_min": 40.0}, "range_min"),
    ],
)
def test_laser_scan_geometry_is_validated(geometry: dict, field: str) -> None:
    with pytest.raises(CodecError, match=f"sensor_msgs/msg/LaserScan.{field}"):
        convert.laser_scan(laser_scan_msg([1.0, 2.0], **geometry), 0, 0.0)


def test_laser_scan_round_trip() -> None:
    rng = np.random.default_rng(11)
    angles = -math.pi + np.arange(360) * (2 * math.pi / 360)
    ranges = rng.uniform(0.2, 8.0, 360)
    ranges[rng.choice(360, 30, replace=False)] = math.inf
    ranges[rng.choice(360, 30, replace=False)] = 0.0
    scan = LidarScan(1, 12.5, angles, ranges, 8.0)
    message = convert.laser_scan_msg(scan, 1_700_000_012.5, "base_scan", 0.12)
    assert np.isnan(message.ranges).sum() == (ranges == 0.0).sum()
    received = convert.laser_scan(through_cdr(message), 1, 12.5)
    assert convert.header_stamp_s(message) == pytest.approx(1_700_000_012.5, abs=1e-6)
    assert convert.frame_id(message) == "base_scan"
    assert received.angles == pytest.approx(angles, abs=1e-5)
    assert np.array_equal(received.ranges == 0.0, ranges == 0.0)
    assert np.array_equal(np.isinf(received.ranges), np.isinf(ranges))
    finite = np.isfinite(ranges)
    assert received.ranges[finite] == pytest.approx(ranges[finite], rel=1e-6)


def test_built_messages_hold_what_cdr_gives_back() -> None:
    """Built messages read back from CDR unchanged, so one replayed from memory equals the
    one from a bag: float32 fields (a CARMEN scan's 180 beams over 180 deg, pi / 179 no
    float32; a 0.05 m map resolution; marker colours) and all the rest."""
    ranges = np.round(np.random.default_rng(3).uniform(0.05, 60.0, 180), 2)
    ranges[[4, 9]] = math.inf, 0.0
    scan = LidarScan(0, 7.0, np.linspace(-math.pi / 2, math.pi / 2, 180), ranges, 50.0)
    stamp_s = 976_052_857.337284
    built = [
        convert.laser_scan_msg(scan, stamp_s, "laser", 0.0),
        convert.odometry_msg(stamp_s, [1.25, -3.5, 2.9], 0.3, -0.1, "odom", "base_link"),
        convert.tf_message([("base_link", "laser", stamp_s, [0.1, 0.02, 0.05])]),
        convert.occupancy_grid_msg(
            np.array([[-1, 0], [100, 0]], dtype=np.int8), GridSpec(-1.5, 2.25, 0.05, 2, 2), 3.0
        ),
        convert.marker_array_msg([[0.1, 0.2]], [[1.0, 2.0]], [], stamp_s),
        convert.path_msg([[0.3, 0.7], [1.1, 1.9]], stamp_s),
        convert.point_cloud_msg([[0.3, -0.2, 0.1]], stamp_s, "base_link"),
        convert.twist_msg(0.3, -0.7, stamped=True, stamp_s=stamp_s),
    ]
    assert built[0].angle_increment != math.pi / 179
    for message in built:
        assert_same_values(message, through_cdr(message), message.__msgtype__)
    decoded = convert.laser_scan(through_cdr(built[0]), 0, 7.0)
    in_memory = convert.laser_scan(built[0], 0, 7.0)
    assert np.array_equal(decoded.angles, in_memory.angles)
    assert np.array_equal(decoded.ranges, in_memory.ranges)


def test_laser_scan_msg_needs_evenly_spaced_beams() -> None:
    uneven = LidarScan(0, 0.0, np.array([0.0, 0.1, 0.3]), np.ones(3), 5.0)
    with pytest.raises(MessageError, match="evenly spaced"):
        convert.laser_scan_msg(uneven, 0.0, "laser", 0.1)
    single = LidarScan(0, 0.0, np.zeros(1), np.ones(1), 5.0)
    with pytest.raises(MessageError, match="2 beams"):
        convert.laser_scan_msg(single, 0.0, "laser", 0.1)


def test_a_real_scan_ends_at_its_angle_max(shared_dataset: Callable[[str], Path]) -> None:
    with Reader(shared_dataset(SCAN_BAG)) as reader:
        connections = [c for c in reader.connections if c.topic == "/scan"]
        _, _, raw = next(iter(reader.messages(connections=connections)))
    cdr = bytes(wire.typestore("jazzy").ros1_to_cdr(raw, "sensor_msgs/msg/LaserScan"))
    message = wire.decode_cdr(cdr, "sensor_msgs/msg/LaserScan", "jazzy")
    scan = convert.laser_scan(message, 0, convert.header_stamp_s(message))
    assert len(scan.ranges) == 681
    assert scan.angles[-1] == pytest.approx(message.angle_max, abs=1e-6)
    assert convert.header_stamp_s(message) == pytest.approx(1282836370.9708765, abs=1e-6)
    assert np.isfinite(scan.ranges).sum() + np.isinf(scan.ranges).sum() == 681


# ------------------------------------------------------------------------------ odometry


def test_odometry_round_trip() -> None:
    message = convert.odometry_msg(3.5, [1.0, 2.0, 0.7], 0.4, -0.2, "odom", "base_footprint")
    stamp_s, xytheta, frame, child = convert.odometry_pose(through_cdr(message))
    assert stamp_s == 3.5
    assert xytheta == pytest.approx([1.0, 2.0, 0.7])
    assert (frame, child) == ("odom", "base_footprint")
    assert convert.twist_command(message.twist.twist) == pytest.approx((0.4, -0.2))


def test_non_finite_odometry_raises() -> None:
    message = convert.odometry_msg(1.0, [0.0, 0.0, 0.0], 0.0, 0.0, "odom", "base_link")
    message.pose.pose.position.x = math.nan
    with pytest.raises(CodecError, match=r"nav_msgs/msg/Odometry.pose.pose.position.x"):
        convert.odometry_pose(message)
    with pytest.raises(MessageError):
        convert.odometry_msg(1.0, [0.0, math.nan, 0.0], 0.0, 0.0, "odom", "base_link")


# ------------------------------------------------------------------------------ PointCloud2


def test_point_cloud_round_trip() -> None:
    rng = np.random.default_rng(2)
    points = rng.uniform(-5.0, 5.0, (25, 3))
    message = through_cdr(convert.point_cloud_msg(points, 1.25, "base_link"))
    assert convert.landmark_points(message) == pytest.approx(points, abs=1e-6)
    observations = convert.landmark_observations(message, 3, 9.0)
    assert isinstance(observations, LandmarkObservations)
    assert observations.points.shape == (25, 3)
    empty = through_cdr(convert.point_cloud_msg(np.empty((0, 3)), 1.0, "base_link"))
    assert convert.landmark_points(empty).shape == (0, 3)


def cloud(
    points: np.ndarray,
    *,
    layout: np.dtype,
    rows: int = 1,
    row_padding_bytes: int = 0,
    is_dense: bool = True,
    **overrides: Any,
) -> Any:
    """A PointCloud2 whose bytes numpy lays out from ``layout`` (a structured dtype)."""
    point_field = T["sensor_msgs/msg/PointField"]
    datatypes = {np.dtype("<f4"): point_field.FLOAT32, np.dtype("<f8"): point_field.FLOAT64}
    records = np.zeros(len(points), dtype=layout)
    for i, axis in enumerate("xyz"):
        records[axis] = points[:, i]
    width = len(points) // rows
    packed = records.tobytes()
    row_bytes = width * layout.itemsize
    data = b"".join(
        packed[r * row_bytes : (r + 1) * row_bytes] + bytes(row_padding_bytes) for r in range(rows)
    )
    fields = [
        point_field(name=name, offset=offset, datatype=datatypes[dtype], count=1)
        for name, (dtype, offset) in layout.fields.items()
    ]
    arguments = {
        "header": T["std_msgs/msg/Header"](stamp=convert.ros_time(1.0), frame_id="camera"),
        "height": rows,
        "width": width,
        "fields": fields,
        "is_bigendian": False,
        "point_step": layout.itemsize,
        "row_step": row_bytes + row_padding_bytes,
        "data": np.frombuffer(data, dtype=np.uint8),
        "is_dense": is_dense,
    }
    return T["sensor_msgs/msg/PointCloud2"](**(arguments | overrides))


PADDED_F64 = np.dtype(
    {
        "names": ["intensity", "z", "x", "y"],
        "formats": ["<f4", "<f8", "<f8", "<f8"],
        "offsets": [0, 8, 16, 24],
        "itemsize": 40,
    }
)
XYZ_F32 = np.dtype({"names": list("xyz"), "formats": ["<f4"] * 3, "offsets": [0, 4, 8]})


def test_point_cloud_reads_declared_offsets_rows_and_float64() -> None:
    points = np.arange(18, dtype=float).reshape(6, 3) / 7.0
    message = through_cdr(cloud(points, layout=PADDED_F64, rows=2, row_padding_bytes=8))
    assert np.array_equal(convert.landmark_points(message), points)


def test_non_dense_cloud_drops_invalid_points_and_a_dense_one_raises() -> None:
    points = np.array([[1.0, 2.0, 3.0], [math.nan, math.nan, math.nan], [4.0, 5.0, 6.0]])
    sparse = cloud(points, layout=XYZ_F32, is_dense=False)
    assert convert.landmark_points(sparse).tolist() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    with pytest.raises(CodecError, match="is_dense"):
        convert.landmark_points(cloud(points, layout=XYZ_F32, is_dense=True))


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"point_step": 8}, "point_step"),
        ({"row_step": 12}, "row_step"),
        ({"data": np.zeros(35, dtype=np.uint8)}, "data"),
        ({"height": 2}, "data"),
        ({"is_bigendian": True}, "is_bigendian"),
        ({"fields": []}, "fields"),
    ],
)
def test_malformed_point_clouds_raise(overrides: dict, field: str) -> None:
    message = cloud(np.ones((3, 3)), layout=XYZ_F32, **overrides)
    with pytest.raises(CodecError, match=f"sensor_msgs/msg/PointCloud2.{field}"):
        convert.landmark_points(message)


def test_point_cloud_refuses_integer_coordinates() -> None:
    message = cloud(np.ones((3, 3)), layout=XYZ_F32)
    message.fields[2].datatype = T["sensor_msgs/msg/PointField"].INT32
    with pytest.raises(CodecError, match=r"fields\['z'\].datatype"):
        convert.landmark_points(message)


# ------------------------------------------------------------------------------ twist


def test_twist_commands() -> None:
    plain = through_cdr(convert.twist_msg(0.3, -0.5))
    assert plain.__msgtype__ == "geometry_msgs/msg/Twist"
    assert convert.twist_command(plain) == (0.3, -0.5)
    stamped = through_cdr(
        convert.twist_msg(0.3, -0.5, "kilted", stamped=True, stamp_s=2.0, frame_id="base_link"),
        "kilted",
    )
    assert stamped.__msgtype__ == "geometry_msgs/msg/TwistStamped"
    assert convert.twist_command(stamped) == (0.3, -0.5)
    assert convert.header_stamp_s(stamped) == 2.0
    with pytest.raises(MessageError, match="stamp_s"):
        convert.twist_msg(0.3, -0.5, stamped=True)


def test_non_finite_twist_raises() -> None:
    message = convert.twist_msg(0.0, 0.0, stamped=True, stamp_s=0.0)
    message.twist.angular.z = math.inf
    with pytest.raises(CodecError, match=r"TwistStamped.twist.angular.z"):
        convert.twist_command(message)
    with pytest.raises(CodecError, match="has no std_msgs/Header"):
        convert.header_stamp_s(convert.twist_msg(0.0, 0.0))


# ------------------------------------------------------------------------------ map output


def test_occupancy_grid_cell_order_matches_ros() -> None:
    spec = GridSpec(origin_x_m=-1.0, origin_y_m=-2.0, resolution_m=0.5, rows=3, cols=4)
    cells = np.full(spec.shape, FREE, dtype=np.int8)
    cells[0, :] = UNKNOWN
    world_xy = np.array([0.3, -0.7])  # near the top right of the grid
    row, col = spec.world_to_cell(world_xy)[0]
    cells[row, col] = OCCUPIED
    message = through_cdr(convert.occupancy_grid_msg(cells, spec, 5.0))
    info = message.info
    assert (info.width, info.height, info.resolution) == (4, 3, 0.5)
    assert (info.origin.position.x, info.origin.position.y) == (-1.0, -2.0)
    # ROS: data is row-major from the origin cell, x along a row (map_server's convention).
    ros_col = math.floor((world_xy[0] - info.origin.position.x) / info.resolution)
    ros_row = math.floor((world_xy[1] - info.origin.position.y) / info.resolution)
    assert np.flatnonzero(message.data == OCCUPIED).tolist() == [ros_row * info.width + ros_col]
    assert message.data[: info.width].tolist() == [UNKNOWN] * 4  # the lowest-y row
    assert convert.header_stamp_s(message) == 5.0 and convert.frame_id(message) == "map"


def test_published_map_is_its_known_box_at_the_same_world_places() -> None:
    spec = GridSpec(origin_x_m=-3.0, origin_y_m=2.0, resolution_m=0.25, rows=40, cols=50)
    cells = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    cells[10:15, 20:32] = FREE
    cells[12, 31] = OCCUPIED
    cells[16, 25] = OCCUPIED  # a wall cell one row past the free area
    message = through_cdr(convert.known_map_msg(cells, spec, 1.0))
    info = message.info
    assert (info.height, info.width) == (7, 12)  # rows 10..16, columns 20..31
    assert (info.origin.position.x, info.origin.position.y) == (-3.0 + 20 * 0.25, 2.0 + 10 * 0.25)
    ros = np.asarray(message.data).reshape(info.height, info.width)
    for row, col in np.argwhere(cells != UNKNOWN):  # every known cell, found by its world x, y
        x, y = spec.cell_to_world(np.array([[row, col]]))[0]
        ros_row = math.floor((y - info.origin.position.y) / info.resolution)
        ros_col = math.floor((x - info.origin.position.x) / info.resolution)
        assert ros[ros_row, ros_col] == cells[row, col]
    assert (ros != UNKNOWN).sum() == (cells != UNKNOWN).sum()


def test_occupancy_grid_refuses_invalid_cells() -> None:
    spec = GridSpec(0.0, 0.0, 0.1, 2, 2)
    with pytest.raises(MessageError, match="lie in"):
        convert.occupancy_grid_msg(np.full((2, 2), 101), spec, 0.0)
    with pytest.raises(MessageError, match="shape"):
        convert.occupancy_grid_msg(np.zeros((2, 3), dtype=np.int8), spec, 0.0)
    with pytest.raises(MessageError, match="integers"):
        convert.occupancy_grid_msg(np.zeros((2, 2)), spec, 0.0)


def test_path() -> None:
    xy = np.array([[0.0, 0.0], [1.0, 0.5], [2.0, 1.5]])
    message = through_cdr(convert.path_msg(xy, 3.0))
    assert [[p.pose.position.x, p.pose.position.y] for p in message.poses] == xy.tolist()
    assert message.header.frame_id == "map"
    assert through_cdr(convert.path_msg(np.empty((0, 2)), 3.0)).poses == []


@pytest.mark.parametrize("distro", wire.DISTROS)
def test_marker_array_replaces_one_marker_per_kind(distro: str) -> None:
    frontiers = np.array([[0.0, 1.0], [0.5, 1.0]])
    message = through_cdr(
        convert.marker_array_msg(frontiers, [np.array([2.0, 3.0])], [], 1.0, "map", distro),
        distro,
    )
    marker = T["visualization_msgs/msg/Marker"]
    summary = [(m.ns, m.id, m.type, m.action, len(m.points)) for m in message.markers]
    assert summary == [
        ("frontiers", 0, marker.POINTS, marker.ADD, 2),
        ("cluster_targets", 0, marker.SPHERE_LIST, marker.ADD, 1),
        ("goals", 0, marker.CUBE_LIST, marker.ADD, 0),
    ]
    assert (message.markers[1].points[0].x, message.markers[1].points[0].y) == (2.0, 3.0)
    with pytest.raises(MessageError, match="goals"):
        convert.marker_array_msg(frontiers, [], [[math.nan, 0.0]], 1.0)


def test_tf_round_trip() -> None:
    message = convert.tf_message(
        [("map", "robot1/odom", 4.5, [1.0, 2.0, 0.5]), ("odom", "base_link", 4.5, [0, 0, -3])]
    )
    transforms = convert.tf_transforms(through_cdr(message))
    assert [(parent, child, stamp) for parent, child, stamp, _ in transforms] == [
        ("map", "robot1/odom", 4.5),
        ("odom", "base_link", 4.5),
    ]
    assert transforms[0][3] == pytest.approx([1.0, 2.0, 0.5])
    assert transforms[1][3] == pytest.approx([0.0, 0.0, -3.0])
    message.transforms[1].child_frame_id = ""
    with pytest.raises(CodecError, match=r"transforms\[1\]"):
        convert.tf_transforms(message)
