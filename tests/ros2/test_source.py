"""What a ROS 2 robot's scans say of its laser frame before the run starts."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.ros2.source import _Robot, _UnknownFrameError


def _robot_with_mount() -> _Robot:
    robot = _Robot(0, "alpha", base_frame="base_footprint", odom_frame="odom")
    robot.tf.add("base_footprint", "base_link", np.array([0.0, 0.0, 0.0]))
    robot.tf.add("base_link", "base_scan", np.array([-0.064, 0.0, 0.0]))
    return robot


def test_a_stray_frame_before_the_start_is_dropped_not_taken() -> None:
    robot = _robot_with_mount()
    robot.take_scan_frame("base_scan")
    with pytest.raises(_UnknownFrameError, match="camera_link"):
        robot.take_scan_frame("camera_link")
    assert robot.scan_frame == "base_scan"
    mount = robot.tf.lookup(robot.base_frame, robot.scan_frame)
    np.testing.assert_allclose(mount, [-0.064, 0.0, 0.0])


def test_the_latest_frame_wins_while_none_joins_the_base() -> None:
    robot = _Robot(0, "alpha", base_frame="base_footprint", odom_frame="odom")
    robot.take_scan_frame("camera_link")  # no tf_static yet: nothing to judge it by
    robot.take_scan_frame("base_scan")
    assert robot.scan_frame == "base_scan"
    robot.tf.add("base_footprint", "base_scan", np.array([0.1, 0.0, 0.0]))
    robot.take_scan_frame("base_scan")  # the same frame again is always taken
    assert robot.scan_frame == "base_scan"


def test_a_frame_that_joins_the_base_replaces_one_that_does_not() -> None:
    robot = _robot_with_mount()
    robot.take_scan_frame("laser_old")  # does not join: replaced by a real one
    robot.take_scan_frame("base_scan")
    assert robot.scan_frame == "base_scan"
