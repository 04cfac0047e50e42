"""Conversions between ROS 2 messages (rosbags message objects) and acslam's.

Decoders take what a ROS node sent, so they validate everything: a wrong message type, a
non-finite value, a non-unit quaternion or an inconsistent array layout raises
:class:`CodecError` naming the message type and field, and no NaN reaches acslam. Builders
take acslam's own values and raise :class:`MessageError` on invalid ones; they build the
types of ``distro`` (the message definitions used here are identical in every distro of
:data:`acslam.ros2.wire.DISTROS`). A built message holds the values its CDR carries (a
float32 field a float32 value), so it equals the message a bag or the wire gives back.

Frames follow REP 103/105: x forward, y left, yaw counter-clockwise about z; a planar pose
is ``[x, y, yaw]`` (m, m, rad).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from acslam.errors import CodecError, MessageError
from acslam.grid import OCCUPIED, UNKNOWN, GridSpec
from acslam.mapping.costmap import known_window
from acslam.messages import LandmarkObservations, LidarScan
from acslam.ros2 import wire

QUATERNION_NORM_TOLERANCE = 1e-3
"""A received quaternion whose norm is further than this from 1 is rejected."""

ANGLE_SPACING_TOLERANCE_RAD = 1e-6
"""LaserScan beams are evenly spaced; acslam angles further than this from even are refused."""

_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_POINT_FIELD_FORMATS = {7: "<f4", 8: "<f8"}  # sensor_msgs/PointField FLOAT32, FLOAT64
_MARKER_Z_M = 0.05  # just above the map plane, so the map does not hide the markers
_MARKER_STYLES = (
    # namespace, marker type, scale (m), colour RGB
    ("frontiers", "POINTS", 0.05, (0.2, 0.4, 1.0)),
    ("cluster_targets", "SPHERE_LIST", 0.25, (1.0, 0.6, 0.0)),
    ("goals", "CUBE_LIST", 0.3, (0.1, 0.8, 0.2)),
)

Message = Any
"""A rosbags message object (its class is generated per typestore, so no static type)."""


def _types(distro: str) -> dict[str, Any]:
    return wire.typestore(distro).types


def _expect(msg: Message, *msgtypes: str) -> str:
    """The message's type, if it is one of ``msgtypes``."""
    msgtype = getattr(msg, "__msgtype__", None)
    if msgtype not in msgtypes:
        found = msgtype or type(msg).__name__
        raise CodecError(f"expected a {' or '.join(msgtypes)}, got {found}")
    return msgtype


def _finite(where: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise CodecError(f"{where}: must be finite, got {value!r}")
    return value


def _float32(value: float) -> float:
    """``value`` as the float32 a message field of that type carries."""
    return float(np.float32(value))


def _check_finite(what: str, values: np.ndarray) -> np.ndarray:
    if not np.isfinite(values).all():
        raise MessageError(f"{what}: must be finite (no NaN or inf)")
    return values


def _xytheta_array(xytheta: ArrayLike) -> np.ndarray:
    pose = np.asarray(xytheta, dtype=float)
    if pose.shape != (3,):
        raise MessageError(f"pose: must be [x, y, yaw], got shape {pose.shape}")
    return _check_finite("pose", pose)


def _xy_array(what: str, xy_m: ArrayLike) -> np.ndarray:
    xy = np.asarray(xy_m, dtype=float)
    if xy.size == 0:
        xy = xy.reshape(0, 2)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise MessageError(f"{what}: must have shape (N, 2), got {xy.shape}")
    return _check_finite(what, xy)


def time_s(stamp: Message, where: str = "builtin_interfaces/msg/Time") -> float:
    """A ``builtin_interfaces/Time`` in seconds (a float64 resolves ~0.24 us of a current
    UNIX time)."""
    if not 0 <= stamp.nanosec < 1_000_000_000:
        raise CodecError(f"{where}.nanosec: must be in [0, 1e9), got {stamp.nanosec}")
    return stamp.sec + stamp.nanosec * 1e-9


def ros_time(stamp_s: float, distro: str = wire.DEFAULT_DISTRO) -> Message:
    """Seconds as a ``builtin_interfaces/Time``, rounded to the nearest ns (nanosec always in
    [0, 1e9), so negative times have a negative ``sec`` and a positive ``nanosec``)."""
    if not math.isfinite(stamp_s):
        raise MessageError(f"stamp: must be finite, got {stamp_s!r}")
    sec = math.floor(stamp_s)
    nanosec = round((stamp_s - sec) * 1e9)
    if nanosec == 1_000_000_000:
        sec, nanosec = sec + 1, 0
    if not _INT32_MIN <= sec <= _INT32_MAX:
        raise MessageError(f"stamp: {stamp_s} s does not fit builtin_interfaces/Time (int32 s)")
    return _types(distro)["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _header_of(msg: Message) -> tuple[str, Message]:
    header = getattr(msg, "header", None)
    if getattr(header, "__msgtype__", None) != "std_msgs/msg/Header":
        found = getattr(msg, "__msgtype__", None) or type(msg).__name__
        raise CodecError(f"{found}: has no std_msgs/Header")
    return msg.__msgtype__, header


def header_stamp_s(msg: Message) -> float:
    """The header stamp of a stamped message, in seconds."""
    where, header = _header_of(msg)
    return time_s(header.stamp, f"{where}.header.stamp")


def frame_id(msg: Message) -> str:
    """The header frame of a stamped message."""
    return _header_of(msg)[1].frame_id


def _header(stamp_s: float, frame_id: str, distro: str) -> Message:
    return _types(distro)["std_msgs/msg/Header"](
        stamp=ros_time(stamp_s, distro=distro), frame_id=frame_id
    )


def _planar(where: str, position: Message, orientation: Message) -> np.ndarray:
    """[x, y, yaw] from a Point/Vector3 and a quaternion (yaw of the ZYX Euler angles)."""
    x = _finite(f"{where}.x", position.x)
    y = _finite(f"{where}.y", position.y)
    q = np.array([orientation.x, orientation.y, orientation.z, orientation.w], dtype=float)
    if not np.isfinite(q).all():
        raise CodecError(f"{where} orientation: quaternion must be finite, got {q.tolist()}")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise CodecError(f"{where} orientation: quaternion norm {norm:.6g} is not 1")
    qx, qy, qz, qw = q / norm
    yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return np.array([x, y, yaw])


def _quaternion(yaw_rad: float, distro: str) -> Message:
    return _types(distro)["geometry_msgs/msg/Quaternion"](
        x=0.0, y=0.0, z=math.sin(0.5 * yaw_rad), w=math.cos(0.5 * yaw_rad)
    )


def planar_pose(msg: Message) -> np.ndarray:
    """``geometry_msgs/Pose`` -> ``[x, y, yaw]``; z, roll and pitch are dropped."""
    _expect(msg, "geometry_msgs/msg/Pose")
    return _planar("geometry_msgs/msg/Pose.position", msg.position, msg.orientation)


def transform_xytheta(msg: Message) -> np.ndarray:
    """``geometry_msgs/Transform`` (e.g. ``TransformStamped.transform``) -> ``[x, y, yaw]``."""
    _expect(msg, "geometry_msgs/msg/Transform")
    return _planar("geometry_msgs/msg/Transform.translation", msg.translation, msg.rotation)


def pose_msg(xytheta: ArrayLike, distro: str = wire.DEFAULT_DISTRO) -> Message:
    """``[x, y, yaw]`` -> ``geometry_msgs/Pose`` in the z = 0 plane."""
    x, y, yaw = _xytheta_array(xytheta)
    point = _types(distro)["geometry_msgs/msg/Point"](x=x, y=y, z=0.0)
    return _types(distro)["geometry_msgs/msg/Pose"](
        position=point, orientation=_quaternion(yaw, distro)
    )


def transform_msg(xytheta: ArrayLike, distro: str = wire.DEFAULT_DISTRO) -> Message:
    """``[x, y, yaw]`` -> ``geometry_msgs/Transform``."""
    x, y, yaw = _xytheta_array(xytheta)
    translation = _types(distro)["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0)
    return _types(distro)["geometry_msgs/msg/Transform"](
        translation=translation, rotation=_quaternion(yaw, distro)
    )


def laser_scan(msg: Message, robot_id: int, stamp_s: float) -> LidarScan:
    """``sensor_msgs/LaserScan`` -> :class:`LidarScan` stamped ``stamp_s`` (the caller maps
    :func:`header_stamp_s` to acslam's clock).

    Beam ``i`` points at ``angle_min + i * angle_increment``. Ranges follow REP 117: +inf
    and readings above ``range_max`` are no return (acslam: inf); NaN, -inf and readings
    below ``range_min`` are invalid (acslam: 0). ``intensities`` are ignored.
    """
    where = _expect(msg, "sensor_msgs/msg/LaserScan")
    angle_min = _finite(f"{where}.angle_min", msg.angle_min)
    increment = _finite(f"{where}.angle_increment", msg.angle_increment)
    if not 0.0 < abs(increment) <= 2.0 * math.pi:
        raise CodecError(f"{where}.angle_increment: must be non-zero and within 2 pi")
    range_max = _finite(f"{where}.range_max", msg.range_max)
    if range_max <= 0.0:
        raise CodecError(f"{where}.range_max: must be > 0, got {range_max}")
    range_min = _finite(f"{where}.range_min", msg.range_min)
    if not 0.0 <= range_min < range_max:
        raise CodecError(f"{where}.range_min: must be in [0, range_max), got {range_min}")
    readings = np.asarray(msg.ranges, dtype=float)
    if readings.ndim != 1:
        raise CodecError(f"{where}.ranges: must be one-dimensional")
    ranges = readings.copy()
    ranges[np.isnan(readings) | (readings < range_min)] = 0.0
    ranges[readings > range_max] = math.inf
    angles = angle_min + np.arange(len(readings)) * increment
    return LidarScan(robot_id, stamp_s, angles, ranges, range_max)


def laser_scan_msg(
    scan: LidarScan,
    stamp_s: float,
    frame_id: str,
    range_min_m: float,
    distro: str = wire.DEFAULT_DISTRO,
) -> Message:
    """:class:`LidarScan` -> ``sensor_msgs/LaserScan`` stamped ``stamp_s`` (the ROS time of
    ``scan.stamp``), for the simulated robot and bags.

    The beams must be evenly spaced (at least two). inf (no return) stays +inf and 0
    (invalid) becomes NaN, per REP 117; a reading in (0, ``range_min_m``) would read as
    invalid on the ROS side. ``scan_time`` and ``time_increment`` are 0 (unknown).
    """
    angles = scan.angles
    if len(angles) < 2:
        raise MessageError("LidarScan.angles: a LaserScan needs at least 2 beams")
    increment = (angles[-1] - angles[0]) / (len(angles) - 1)
    even = angles[0] + np.arange(len(angles)) * increment
    if increment == 0.0 or np.abs(angles - even).max() > ANGLE_SPACING_TOLERANCE_RAD:
        raise MessageError("LidarScan.angles: must be distinct and evenly spaced for a LaserScan")
    if not 0.0 <= range_min_m < scan.range_max_m:
        raise MessageError(f"range_min_m: must be in [0, range_max_m), got {range_min_m}")
    ranges = scan.ranges.astype(np.float32)
    ranges[scan.ranges == 0.0] = np.nan
    return _types(distro)["sensor_msgs/msg/LaserScan"](
        header=_header(stamp_s, frame_id, distro),
        angle_min=_float32(angles[0]),
        angle_max=_float32(angles[-1]),
        angle_increment=_float32(increment),
        time_increment=0.0,
        scan_time=0.0,
        range_min=_float32(range_min_m),
        range_max=_float32(scan.range_max_m),
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def odometry_pose(msg: Message) -> tuple[float, np.ndarray, str, str]:
    """``nav_msgs/Odometry`` -> (header stamp s, ``[x, y, yaw]``, frame, child frame): the
    pose of the child frame (the robot base) in the frame (odom). The frames come back so
    the caller can reject a pose in a frame it does not expect."""
    where = _expect(msg, "nav_msgs/msg/Odometry")
    pose = msg.pose.pose
    xytheta = _planar(f"{where}.pose.pose.position", pose.position, pose.orientation)
    return header_stamp_s(msg), xytheta, msg.header.frame_id, msg.child_frame_id


def odometry_msg(
    stamp_s: float,
    xytheta: ArrayLike,
    v_mps: float,
    omega_radps: float,
    frame_id: str,
    child_frame_id: str,
    distro: str = wire.DEFAULT_DISTRO,
) -> Message:
    """A ``nav_msgs/Odometry`` with the pose in ``frame_id`` and the velocity in
    ``child_frame_id`` (REP 105); covariances are zero (unknown)."""
    types = _types(distro)
    zeros = np.zeros(36, dtype=np.float64)
    return types["nav_msgs/msg/Odometry"](
        header=_header(stamp_s, frame_id, distro),
        child_frame_id=child_frame_id,
        pose=types["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose_msg(xytheta, distro=distro), covariance=zeros
        ),
        twist=types["geometry_msgs/msg/TwistWithCovariance"](
            twist=_twist(v_mps, omega_radps, distro), covariance=zeros.copy()
        ),
    )


def landmark_points(msg: Message) -> np.ndarray:
    """``sensor_msgs/PointCloud2`` -> (N, 3) float64 ``[x, y, z]`` (m, in the cloud's frame).

    Reads the x, y, z fields (FLOAT32 or FLOAT64, little-endian) at the offsets the
    message declares, whatever else each point holds. Non-finite points mark invalid
    returns in a cloud with ``is_dense`` false and are dropped; in a dense cloud they are
    an error.
    """
    where = _expect(msg, "sensor_msgs/msg/PointCloud2")
    if msg.is_bigendian:
        raise CodecError(f"{where}.is_bigendian: big-endian clouds are not supported")
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    fields = {field.name: field for field in msg.fields}
    formats = []
    for axis in "xyz":
        field = fields.get(axis)
        if field is None:
            raise CodecError(f"{where}.fields: no {axis!r} field")
        fmt = _POINT_FIELD_FORMATS.get(field.datatype)
        if fmt is None:
            raise CodecError(
                f"{where}.fields[{axis!r}].datatype: {field.datatype} is not FLOAT32 (7)"
                " or FLOAT64 (8)"
            )
        if field.count != 1:
            raise CodecError(f"{where}.fields[{axis!r}].count: must be 1, got {field.count}")
        size = np.dtype(fmt).itemsize
        if field.offset + size > point_step:
            raise CodecError(
                f"{where}.point_step: {point_step} bytes cannot hold field {axis!r} at"
                f" offset {field.offset} ({size} bytes)"
            )
        formats.append(fmt)
    if row_step < width * point_step:
        raise CodecError(
            f"{where}.row_step: {row_step} bytes is less than width * point_step"
            f" = {width * point_step}"
        )
    data = np.asarray(msg.data, dtype=np.uint8)
    if data.size != height * row_step:
        raise CodecError(
            f"{where}.data: {data.size} bytes, expected height * row_step = {height * row_step}"
        )
    point_dtype = np.dtype(
        {
            "names": list("xyz"),
            "formats": formats,
            "offsets": [fields[axis].offset for axis in "xyz"],
            "itemsize": point_step,
        }
    )
    rows = np.ascontiguousarray(data.reshape(height, row_step)[:, : width * point_step])
    cloud = rows.view(point_dtype).reshape(-1)
    points = np.stack([cloud[axis].astype(float) for axis in "xyz"], axis=1)
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        if msg.is_dense:
            raise CodecError(f"{where}.is_dense: set, but {np.sum(~finite)} points are not finite")
        points = points[finite]
    return points


def landmark_observations(msg: Message, robot_id: int, stamp_s: float) -> LandmarkObservations:
    """``sensor_msgs/PointCloud2`` of landmark points in the robot frame ->
    :class:`LandmarkObservations` stamped ``stamp_s`` (see :func:`landmark_points`)."""
    return LandmarkObservations(robot_id, stamp_s, landmark_points(msg))


def point_cloud_msg(
    points: ArrayLike, stamp_s: float, frame_id: str, distro: str = wire.DEFAULT_DISTRO
) -> Message:
    """(N, 3) points (m) -> a dense, unordered ``sensor_msgs/PointCloud2`` of float32 x, y, z."""
    xyz = np.asarray(points, dtype=float)
    if xyz.size == 0:
        xyz = xyz.reshape(0, 3)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise MessageError(f"points: must have shape (N, 3), got {xyz.shape}")
    _check_finite("points", xyz)
    types = _types(distro)
    point_field = types["sensor_msgs/msg/PointField"]
    point_step = 3 * 4
    return types["sensor_msgs/msg/PointCloud2"](
        header=_header(stamp_s, frame_id, distro),
        height=1,
        width=len(xyz),
        fields=[
            point_field(name=axis, offset=4 * i, datatype=point_field.FLOAT32, count=1)
            for i, axis in enumerate("xyz")
        ],
        is_bigendian=False,
        point_step=point_step,
        row_step=point_step * len(xyz),
        data=np.frombuffer(xyz.astype("<f4").tobytes(), dtype=np.uint8),
        is_dense=True,
    )


def twist_command(msg: Message) -> tuple[float, float]:
    """``geometry_msgs/Twist`` or ``TwistStamped`` -> (v m/s, omega rad/s) of a planar robot
    (``linear.x``, ``angular.z``; the other components are ignored)."""
    where = _expect(msg, "geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
    twist = msg
    if where == "geometry_msgs/msg/TwistStamped":
        twist, where = msg.twist, f"{where}.twist"
    return _finite(f"{where}.linear.x", twist.linear.x), _finite(
        f"{where}.angular.z", twist.angular.z
    )


def _twist(v_mps: float, omega_radps: float, distro: str) -> Message:
    _check_finite("twist", np.array([v_mps, omega_radps], dtype=float))
    vector3 = _types(distro)["geometry_msgs/msg/Vector3"]
    return _types(distro)["geometry_msgs/msg/Twist"](
        linear=vector3(x=float(v_mps), y=0.0, z=0.0),
        angular=vector3(x=0.0, y=0.0, z=float(omega_radps)),
    )


def twist_msg(
    v_mps: float,
    omega_radps: float,
    distro: str = wire.DEFAULT_DISTRO,
    *,
    stamped: bool = False,
    stamp_s: float | None = None,
    frame_id: str = "",
) -> Message:
    """(v m/s, omega rad/s) -> ``geometry_msgs/Twist``, or with ``stamped`` a
    ``TwistStamped`` (``stamp_s`` required), which ros2_control's diff drive controller
    requires from Jazzy on and Nav2 sends with ``enable_stamped_cmd_vel``."""
    twist = _twist(v_mps, omega_radps, distro)
    if not stamped:
        return twist
    if stamp_s is None:
        raise MessageError("twist: a TwistStamped needs stamp_s")
    return _types(distro)["geometry_msgs/msg/TwistStamped"](
        header=_header(stamp_s, frame_id, distro), twist=twist
    )


def occupancy_grid_msg(
    cells: np.ndarray,
    spec: GridSpec,
    stamp_s: float,
    frame_id: str = "map",
    distro: str = wire.DEFAULT_DISTRO,
) -> Message:
    """An acslam grid (-1 unknown, 0 free, 100 occupied) -> ``nav_msgs/OccupancyGrid``.

    Both are row-major with row 0 at the origin (the lowest y) and x along the columns, so
    the cells are written as they are: ROS cell ``data[row * width + col]`` is acslam cell
    ``cells[row, col]`` (see :class:`acslam.grid.GridSpec`).
    """
    values = np.asarray(cells)
    if values.shape != spec.shape:
        raise MessageError(f"cells: shape {values.shape} differs from the grid's {spec.shape}")
    if not np.issubdtype(values.dtype, np.integer):
        raise MessageError(f"cells: must be integers, got {values.dtype}")
    if values.size and (values.min() < UNKNOWN or values.max() > OCCUPIED):
        raise MessageError(f"cells: must lie in [{UNKNOWN}, {OCCUPIED}]")
    geometry = np.array([spec.origin_x_m, spec.origin_y_m, spec.resolution_m])
    if not np.isfinite(geometry).all() or spec.resolution_m <= 0.0:
        raise MessageError(f"spec: origin must be finite and resolution > 0, got {spec}")
    stamp = ros_time(stamp_s, distro=distro)
    types = _types(distro)
    info = types["nav_msgs/msg/MapMetaData"](
        map_load_time=stamp,
        resolution=_float32(spec.resolution_m),
        width=spec.cols,
        height=spec.rows,
        origin=pose_msg([spec.origin_x_m, spec.origin_y_m, 0.0], distro=distro),
    )
    return types["nav_msgs/msg/OccupancyGrid"](
        header=types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id),
        info=info,
        data=np.ascontiguousarray(values, dtype=np.int8).reshape(-1),
    )


def known_map_msg(
    cells: np.ndarray,
    spec: GridSpec,
    stamp_s: float,
    frame_id: str = "map",
    distro: str = wire.DEFAULT_DISTRO,
) -> Message:
    """The team map as published: only the bounding box of its known cells, its origin
    moved to match, as slam_toolbox's map grows with what is known.

    The server's grid has a fixed extent and is mostly unknown for much of a run; sent
    whole every second it is most of the team's bandwidth (thesis-exp1: 0.6 MB/s).
    """
    window = known_window(cells, spec, margin_m=0.0)
    return occupancy_grid_msg(window.crop(cells), window.spec, stamp_s, frame_id, distro)


def path_msg(
    xy_m: ArrayLike, stamp_s: float, frame_id: str = "map", distro: str = wire.DEFAULT_DISTRO
) -> Message:
    """(N, 2) waypoints (m) -> ``nav_msgs/Path`` (identity orientations: the path is for
    display, not for a controller that needs headings)."""
    xy = _xy_array("path", xy_m)
    types = _types(distro)
    header = _header(stamp_s, frame_id, distro)
    pose_stamped = types["geometry_msgs/msg/PoseStamped"]
    poses = [pose_stamped(header=header, pose=pose_msg([x, y, 0.0], distro=distro)) for x, y in xy]
    return types["nav_msgs/msg/Path"](header=header, poses=poses)


def marker_array_msg(
    frontiers_xy: ArrayLike,
    targets_xy: ArrayLike,
    goals_xy: ArrayLike,
    stamp_s: float,
    frame_id: str = "map",
    distro: str = wire.DEFAULT_DISTRO,
) -> Message:
    """Frontier cells, cluster targets and goals (each (N, 2), m) as a
    ``visualization_msgs/MarkerArray``: one marker per kind, in namespaces ``frontiers``,
    ``cluster_targets`` and ``goals``, always id 0 and action ADD, so each array replaces
    the previous one in RViz (an empty kind clears its marker)."""
    types = _types(distro)
    marker = types["visualization_msgs/msg/Marker"]
    point = types["geometry_msgs/msg/Point"]
    header = _header(stamp_s, frame_id, distro)
    no_bytes = np.zeros(0, dtype=np.uint8)
    markers = []
    for (namespace, kind, scale_m, rgb), xy_m in zip(
        _MARKER_STYLES, (frontiers_xy, targets_xy, goals_xy), strict=True
    ):
        xy = _xy_array(namespace, xy_m)
        markers.append(
            marker(
                header=header,
                ns=namespace,
                id=0,
                type=getattr(marker, kind),
                action=marker.ADD,
                pose=pose_msg([0.0, 0.0, 0.0], distro=distro),
                scale=types["geometry_msgs/msg/Vector3"](x=scale_m, y=scale_m, z=scale_m),
                color=types["std_msgs/msg/ColorRGBA"](
                    r=_float32(rgb[0]), g=_float32(rgb[1]), b=_float32(rgb[2]), a=1.0
                ),
                lifetime=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
                frame_locked=False,
                points=[point(x=x, y=y, z=_MARKER_Z_M) for x, y in xy],
                colors=[],
                texture_resource="",
                texture=types["sensor_msgs/msg/CompressedImage"](
                    header=header, format="", data=no_bytes
                ),
                uv_coordinates=[],
                text="",
                mesh_resource="",
                mesh_file=types["visualization_msgs/msg/MeshFile"](filename="", data=no_bytes),
                mesh_use_embedded_materials=False,
            )
        )
    return types["visualization_msgs/msg/MarkerArray"](markers=markers)


def tf_message(
    transforms: Iterable[tuple[str, str, float, ArrayLike]],
    distro: str = wire.DEFAULT_DISTRO,
) -> Message:
    """``(parent frame, child frame, stamp s, [x, y, yaw] of child in parent)`` tuples ->
    ``tf2_msgs/TFMessage``."""
    types = _types(distro)
    stamped = types["geometry_msgs/msg/TransformStamped"]
    return types["tf2_msgs/msg/TFMessage"](
        transforms=[
            stamped(
                header=_header(stamp, parent, distro),
                child_frame_id=child,
                transform=transform_msg(xytheta, distro=distro),
            )
            for parent, child, stamp, xytheta in transforms
        ]
    )


def tf_transforms(msg: Message) -> list[tuple[str, str, float, np.ndarray]]:
    """``tf2_msgs/TFMessage`` -> ``(parent frame, child frame, stamp s, [x, y, yaw] of child
    in parent)`` tuples, the inverse of :func:`tf_message`."""
    where = _expect(msg, "tf2_msgs/msg/TFMessage")
    transforms = []
    for i, stamped in enumerate(msg.transforms):
        item = f"{where}.transforms[{i}]"
        parent, child = stamped.header.frame_id, stamped.child_frame_id
        if not parent or not child:
            raise CodecError(f"{item}: frame ids must not be empty ({parent!r} -> {child!r})")
        stamp = time_s(stamped.header.stamp, f"{item}.header.stamp")
        pose = stamped.transform
        xytheta = _planar(f"{item}.transform.translation", pose.translation, pose.rotation)
        transforms.append((parent, child, stamp, xytheta))
    return transforms
