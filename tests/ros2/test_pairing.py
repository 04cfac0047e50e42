"""Odometry and sensor messages on one time line: interpolation, late scans, the mount."""

from __future__ import annotations

import numpy as np
import pytest

from acslam.geometry import compose, transform_points
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement
from acslam.ros2.pairing import OdometryPairing, interpolate_pose


def _scan(stamp_s: float, ranges: list[float]) -> LidarScan:
    angles = np.linspace(-1.0, 1.0, len(ranges))
    return LidarScan(0, stamp_s, angles, np.array(ranges), 8.0)


def _replay(increments: list) -> np.ndarray:
    """The pose the increments compose to from the origin."""
    pose = np.zeros(3)
    for message in increments:
        if isinstance(message, OdometryIncrement):
            pose = compose(pose, message.delta)
    return pose


def test_interpolation_is_linear_and_takes_the_short_way_round() -> None:
    a, b = np.array([0.0, 0.0, 3.0]), np.array([1.0, 2.0, -3.0])
    mid = interpolate_pose(0.0, a, 2.0, b, 1.0)
    np.testing.assert_allclose(mid[:2], [0.5, 1.0])
    # From 3 rad to -3 rad the short way passes pi: half way is pi (or -pi), not 0.
    assert abs(abs(mid[2]) - np.pi) < 1e-12
    assert interpolate_pose(0.0, a, 2.0, b, 2.0) is not b
    np.testing.assert_array_equal(interpolate_pose(0.0, a, 2.0, b, 2.0), b)


def test_a_scan_between_two_odometry_samples_sits_at_the_interpolated_pose() -> None:
    pairing = OdometryPairing(0)
    assert pairing.odometry(0.0, np.zeros(3)) == []
    scan = _scan(0.25, [1.0, 2.0, 3.0])
    assert pairing.scan(scan) == []  # waits for odometry past its stamp
    released = pairing.odometry(1.0, np.array([1.0, 0.0, 0.4]))
    assert [type(m).__name__ for m in released] == [
        "OdometryIncrement",
        "LidarScan",
        "OdometryIncrement",
    ]
    first, delivered, second = released
    assert (first.start_stamp, first.stamp, second.start_stamp, second.stamp) == (0, 0.25, 0.25, 1)
    np.testing.assert_allclose(_replay([first]), [0.25, 0.0, 0.1], atol=1e-12)
    assert delivered is scan  # on time: unchanged
    np.testing.assert_allclose(_replay(released), [1.0, 0.0, 0.4], atol=1e-12)


def test_a_late_scan_is_moved_into_the_frame_of_the_newest_pose() -> None:
    pairing = OdometryPairing(0)
    pairing.odometry(0.0, np.zeros(3))
    pairing.odometry(1.0, np.array([1.0, 0.0, 0.0]))
    pairing.odometry(2.0, np.array([1.0, 1.0, np.pi / 2]))
    late = _scan(0.5, [2.0, np.inf, 0.0])
    (moved,) = pairing.scan(late)
    # Measured at (0.5, 0, 0): the hit of the first beam is at the same world point.
    world_then = transform_points(
        np.array([0.5, 0.0, 0.0]), 2.0 * np.array([[np.cos(-1.0), np.sin(-1.0)]])
    )
    world_now = transform_points(
        np.array([1.0, 1.0, np.pi / 2]),
        moved.ranges[0] * np.array([[np.cos(moved.angles[0]), np.sin(moved.angles[0])]]),
    )
    np.testing.assert_allclose(world_now, world_then, atol=1e-12)
    # No return and invalid beams keep their meaning; only their direction turns.
    assert np.isinf(moved.ranges[1]) and moved.ranges[2] == 0.0
    np.testing.assert_allclose(moved.angles[1:], late.angles[1:] - np.pi / 2)


def test_what_cannot_be_placed_is_counted_not_raised() -> None:
    pairing = OdometryPairing(0, history_s=1.0)
    assert pairing.scan(_scan(-1.0, [1.0])) == []
    pairing.odometry(0.0, np.zeros(3))
    assert pairing.dropped["before the first odometry"] == 1
    for k in range(1, 6):
        pairing.odometry(float(k), np.array([k, 0.0, 0.0]))
    assert pairing.odometry(3.0, np.array([9.0, 9.0, 0.0])) == []
    assert pairing.scan(_scan(0.5, [1.0])) == []
    assert pairing.dropped == {
        "before the first odometry": 1,
        "odometry out of order": 1,
        "older than the odometry history": 1,
    }


def test_the_state_is_the_laser_frame_of_an_offset_mount() -> None:
    mount = np.array([-0.032, 0.0, 0.0])  # TurtleBot3's base_scan
    pairing = OdometryPairing(0, mount)
    pairing.odometry(0.0, np.zeros(3))
    released = pairing.odometry(1.0, np.array([0.0, 0.0, np.pi / 2]))
    # Turning on the spot moves the laser, which sits behind the axle, on a 3.2 cm circle.
    laser_end = compose(compose(np.zeros(3), mount), released[0].delta)
    np.testing.assert_allclose(
        laser_end, compose(np.array([0.0, 0.0, np.pi / 2]), mount), atol=1e-12
    )
    stamp, base = pairing.latest
    assert stamp == 1.0 and np.allclose(base, [0.0, 0.0, np.pi / 2])
    # A landmark 1 m ahead of the base is 1.032 m ahead of the laser.
    (observed,) = pairing.landmarks(LandmarkObservations(0, 1.0, np.array([[1.0, 0.0, 0.5]])))
    np.testing.assert_allclose(observed.points, [[1.032, 0.0, 0.5]], atol=1e-12)
    with pytest.raises(ValueError, match="mount"):
        pairing.set_mount(np.zeros(3))


def test_stream_order_matches_one_built_by_hand_for_a_recording() -> None:
    """Messages of a recording played in stamp order come out as the simulator would send
    them: each sensor message right after the increment that reaches its stamp."""
    rng = np.random.default_rng(4)
    pairing = OdometryPairing(0)
    poses = np.cumsum(rng.normal(0.0, 0.05, (21, 3)), axis=0)
    stream = []
    for k, pose in enumerate(poses):
        stream += pairing.odometry(0.1 * k, pose)
        if k % 2 == 0:
            stream += pairing.scan(_scan(0.1 * k, [1.0]))
    kinds = "".join("o" if isinstance(m, OdometryIncrement) else "s" for m in stream)
    assert kinds == "s" + "oos" * 10
    np.testing.assert_allclose(compose(poses[0], _replay(stream)), poses[-1], atol=1e-12)
