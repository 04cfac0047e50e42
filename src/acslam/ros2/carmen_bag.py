"""``acslam convert carmen``: a CARMEN log's real odometry and laser as a rosbag2 in MCAP
storage, for Foxglove, ROS 2 tools and ``acslam slam rosbag``. ``acslam slam carmen``
replays the same messages, held in memory (:class:`~acslam.ros2.bag.MemoryBag`), so the
log enters SLAM one way, at the ROS messages' precision.

One robot, topics at the root:

- ``/scan``: a ``sensor_msgs/LaserScan`` per FLASER line, frame ``laser``. ``range_max``
  is :data:`~acslam.datasets.carmen.NO_RETURN_RANGE_M`, so what the CARMEN reader calls
  no return (a reading at or above it) stays +inf and every other reading is a return;
  ``range_min`` is 0 (a 0 reading is invalid, written NaN, per REP 117). Ranges, the
  first beam's angle and the angle increment are float32, as the message defines them:
  a relative change under 6e-8 (< 3 um at 50 m), far below the log's 1 cm resolution.
- ``/odom``: ``nav_msgs/Odometry``, ``odom -> base_link``, one sample per stamp. At a
  FLASER line's stamp it is the base pose the line's laser pose implies (the laser pose
  composed with the inverse mount); elsewhere it is the ODOM line's pose as it is. A FLASER
  line's own laser pose is where its scan was taken (the fixed mount is only the median
  over the log), so a replay sees the laser poses the log gives. The velocity is the
  latest ODOM line's.
- ``/tf``: ``odom -> base_link`` with every odometry sample, so viewers can place the
  scans; ``/tf_static``: ``base_link -> laser``, the log's fixed mount
  (:func:`acslam.datasets.carmen.laser_offset`), transient local.

Stamps are the logger timestamps (the order the log plays in; its ipc stamps step back in
time), moved by a whole number of seconds to the UNIX time of the first ipc stamp: the bag
is dated when the log was recorded, and the fractions stay exact in nanoseconds.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np

from acslam.datasets.carmen import (
    NO_RETURN_RANGE_M,
    CarmenLog,
    LaserRecord,
    OdometryRecord,
    laser_offset,
    read_carmen,
)
from acslam.errors import DataError, MessageError
from acslam.geometry import between, compose
from acslam.messages import LidarScan
from acslam.ros2 import convert, wire
from acslam.ros2.bag import BagWriter, MemoryBag

ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
LASER_FRAME = "laser"


def write_carmen(log: CarmenLog, bag: BagWriter | MemoryBag) -> dict:
    """Write ``log`` into ``bag`` as the messages above; returns what it wrote: scans,
    odometry samples, the mount and the time span."""
    distro = bag.distro
    if not log.scans:
        raise DataError(log.path, "no usable FLASER line")
    mount = laser_offset(log)
    inverse_mount = between(mount, np.zeros(3))
    first = log.records[0]
    clock_offset_s = math.floor(first.ipc_stamp_s - first.stamp_s)
    velocity = (0.0, 0.0)
    samples = 0
    stamp_s = first.stamp_s + clock_offset_s
    mount_tf = convert.tf_message([(BASE_FRAME, LASER_FRAME, stamp_s, mount)], distro)
    bag.write("/tf_static", mount_tf, stamp_s, latched=True)
    for logger_s, group in itertools.groupby(log.records, key=lambda r: r.stamp_s):
        records = list(group)
        stamp_s = logger_s + clock_offset_s
        scans = [r for r in records if isinstance(r, LaserRecord)]
        odometry = [r for r in records if isinstance(r, OdometryRecord)]
        if odometry:
            velocity = (odometry[-1].velocity_mps, odometry[-1].yaw_rate_radps)
        if scans:
            base_pose = compose(scans[-1].laser_pose_xytheta, inverse_mount)
        else:
            base_pose = odometry[-1].pose_xytheta
        bag.write(
            "/odom",
            convert.odometry_msg(stamp_s, base_pose, *velocity, ODOM_FRAME, BASE_FRAME, distro),
            stamp_s,
        )
        transform = [(ODOM_FRAME, BASE_FRAME, stamp_s, base_pose)]
        bag.write("/tf", convert.tf_message(transform, distro), stamp_s)
        samples += 1
        for record in scans:
            scan = LidarScan(0, stamp_s, record.angles_rad, record.ranges_m, NO_RETURN_RANGE_M)
            try:
                message = convert.laser_scan_msg(scan, stamp_s, LASER_FRAME, 0.0, distro)
            except MessageError as exc:
                raise DataError(log.path, f"FLASER: {exc}", record.line) from None
            bag.write("/scan", message, stamp_s)
    return {
        "scans": len(log.scans),
        "odometry_samples": samples,
        "mount_xytheta": mount.tolist(),
        "duration_s": float(log.records[-1].stamp_s - first.stamp_s),
    }


def convert_carmen(
    log_path: str | Path, out_path: str | Path, distro: str = wire.DEFAULT_DISTRO
) -> dict:
    """Write the log at ``log_path`` as the MCAP file ``out_path`` (see
    :func:`write_carmen`)."""
    log = read_carmen(log_path)
    with BagWriter(out_path, distro) as bag:
        return write_carmen(log, bag)
