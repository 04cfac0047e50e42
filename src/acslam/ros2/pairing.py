"""Odometry and sensor messages on one time line.

A ROS robot publishes ``odom``, ``scan`` and landmarks on separate topics, each at its own
rate and with its own latency. acslam's localizer instead takes one ordered stream in
which a scan belongs to the pose the odometry increments before it have reached (as the
simulator sends them). :class:`OdometryPairing` turns the first into the second, per
robot:

- every odometry sample becomes an :class:`~acslam.messages.OdometryIncrement` from the
  last one;
- a scan or landmark frame stamped between two odometry samples is placed at the
  odometry interpolated at its stamp: an increment up to that pose, then the message;
- one stamped after the newest odometry waits for the sample that passes it (a recording
  played in stamp order never needs more);
- one stamped before the newest odometry (it arrived late, as live scans do) is moved
  into the frame of the newest pose from the interpolated pose at its stamp, so the
  localizer, which attaches a scan to the robot's current odometry, places its points
  where they were measured.

The robot's state is its *laser* frame, as in the CARMEN replays: odometry poses of the
base are composed with the base-to-laser mount, and landmark points (published in the base
frame) are moved into the laser frame. Scans then need no change, and a laser mounted off
the base centre costs nothing.
"""

from __future__ import annotations

import bisect
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from acslam.geometry import between, compose, transform_points, wrap_angle
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, RobotMessage

MAX_PENDING = 100
"""Sensor messages held for odometry at most; beyond, the oldest is dropped (a robot
whose odometry stopped)."""


def interpolate_pose(
    stamp_a_s: float, pose_a: np.ndarray, stamp_b_s: float, pose_b: np.ndarray, stamp_s: float
) -> np.ndarray:
    """The pose at ``stamp_s`` between two stamped poses: linear in position, along the
    shorter arc in heading; exactly an end pose at its own stamp."""
    if stamp_s == stamp_b_s:
        return pose_b.copy()
    if stamp_s == stamp_a_s:
        return pose_a.copy()
    alpha = (stamp_s - stamp_a_s) / (stamp_b_s - stamp_a_s)
    xy = pose_a[:2] + alpha * (pose_b[:2] - pose_a[:2])
    theta = wrap_angle(pose_a[2] + alpha * wrap_angle(pose_b[2] - pose_a[2]))
    return np.array([xy[0], xy[1], theta])


@dataclass(frozen=True)
class _Sample:
    stamp_s: float
    pose: np.ndarray  # laser frame, in the odometry frame


class OdometryPairing:
    """One robot's odometry, scans and landmark frames as an ordered message stream.

    ``mount_xytheta`` is the laser's pose in the base frame; ``history_s`` how far back a
    late sensor message may still be placed. ``dropped`` counts what could not be placed,
    by reason.
    """

    def __init__(
        self, robot_id: int, mount_xytheta: np.ndarray | None = None, history_s: float = 2.0
    ) -> None:
        self.robot_id = robot_id
        self.mount = np.zeros(3) if mount_xytheta is None else np.asarray(mount_xytheta, float)
        self.history_s = history_s
        self.dropped: Counter[str] = Counter()
        self._history: deque[_Sample] = deque()
        self._pending: list[tuple[float, int, RobotMessage]] = []
        self._arrivals = 0
        self._base_pose: np.ndarray | None = None

    @property
    def latest(self) -> tuple[float, np.ndarray] | None:
        """Stamp and *base* pose (odometry frame) of the newest odometry sample passed on:
        the pose the localizer's latest estimate belongs to."""
        if not self._history or self._base_pose is None:
            return None
        return self._history[-1].stamp_s, self._base_pose.copy()

    def set_mount(self, mount_xytheta: np.ndarray) -> None:
        """The laser's mount pose, once known (e.g. from ``tf_static``); before the first
        odometry sample only, since poses already passed on are in the old frame."""
        if self._history:
            raise ValueError("the mount cannot change after odometry has been passed on")
        self.mount = np.asarray(mount_xytheta, dtype=float)

    def odometry(self, stamp_s: float, base_pose: np.ndarray) -> list[RobotMessage]:
        """A sample of the odometry pose of the base; returns the messages it releases."""
        pose = compose(np.asarray(base_pose, dtype=float), self.mount)
        out: list[RobotMessage] = []
        if not self._history:
            for held_s, _, message in self._take_pending(stamp_s):
                if held_s == stamp_s:
                    out.append(message)
                else:
                    self.dropped["before the first odometry"] += 1
            self._append(_Sample(stamp_s, pose), base_pose)
            return out
        last = self._history[-1]
        if stamp_s <= last.stamp_s:
            self.dropped["odometry out of order"] += 1
            return out
        for held_s, _, message in self._take_pending(stamp_s):
            at = interpolate_pose(last.stamp_s, last.pose, stamp_s, pose, held_s)
            if held_s > last.stamp_s:
                out.append(self._increment(last, _Sample(held_s, at)))
                last = _Sample(held_s, at)
                self._append(last, None)
            out.append(message)
        out.append(self._increment(last, _Sample(stamp_s, pose)))
        self._append(_Sample(stamp_s, pose), base_pose)
        return out

    def scan(self, scan: LidarScan) -> list[RobotMessage]:
        """A scan in the laser frame; returns the messages it releases (none if it waits)."""
        return self._sensor(scan)

    def landmarks(self, observations: LandmarkObservations) -> list[RobotMessage]:
        """Landmark points in the base frame; moved into the laser frame here."""
        inverse_mount = between(self.mount, np.zeros(3))
        points = observations.points.copy()
        points[:, :2] = transform_points(inverse_mount, points[:, :2])
        moved = LandmarkObservations(
            observations.robot_id,
            observations.stamp,
            points,
            observations.descriptors,
            observations.ids,
        )
        return self._sensor(moved)

    # ------------------------------------------------------------------ internals

    def _sensor(self, message: LidarScan | LandmarkObservations) -> list[RobotMessage]:
        stamp_s = message.stamp
        if not self._history or stamp_s > self._history[-1].stamp_s:
            if len(self._pending) >= MAX_PENDING:
                self._pending.pop(0)
                self.dropped["no odometry"] += 1
            self._arrivals += 1
            bisect.insort(self._pending, (stamp_s, self._arrivals, message), key=lambda h: h[:2])
            return []
        current = self._history[-1]
        if stamp_s == current.stamp_s:
            return [message]
        at = self._pose_at(stamp_s)
        if at is None:
            self.dropped["older than the odometry history"] += 1
            return []
        return [_moved(message, between(current.pose, at))]

    def _take_pending(self, until_s: float) -> list[tuple[float, int, RobotMessage]]:
        count = bisect.bisect_right([h[0] for h in self._pending], until_s)
        taken, self._pending = self._pending[:count], self._pending[count:]
        return taken

    def _pose_at(self, stamp_s: float) -> np.ndarray | None:
        stamps = [s.stamp_s for s in self._history]
        after = bisect.bisect_left(stamps, stamp_s)
        if after == 0:
            return None
        a, b = self._history[after - 1], self._history[after]
        return interpolate_pose(a.stamp_s, a.pose, b.stamp_s, b.pose, stamp_s)

    def _append(self, sample: _Sample, base_pose: np.ndarray | None) -> None:
        self._history.append(sample)
        if base_pose is not None:
            self._base_pose = np.asarray(base_pose, dtype=float).copy()
        while len(self._history) > 2 and sample.stamp_s - self._history[1].stamp_s > self.history_s:
            self._history.popleft()

    def _increment(self, start: _Sample, end: _Sample) -> OdometryIncrement:
        dx, dy, dtheta = between(start.pose, end.pose)
        return OdometryIncrement(self.robot_id, end.stamp_s, start.stamp_s, dx, dy, dtheta)


def _moved(
    message: LidarScan | LandmarkObservations, relative: np.ndarray
) -> LidarScan | LandmarkObservations:
    """``message`` re-expressed from the pose it was measured at to one ``relative`` to it
    (``relative`` = the measuring pose in the new frame)."""
    if isinstance(message, LandmarkObservations):
        points = message.points.copy()
        points[:, :2] = transform_points(relative, points[:, :2])
        return LandmarkObservations(
            message.robot_id, message.stamp, points, message.descriptors, message.ids
        )
    ranges = message.ranges
    hit = np.isfinite(ranges) & (ranges > 0)
    angles = message.angles + relative[2]
    new_ranges = ranges.copy()
    if hit.any():
        ends = np.column_stack([np.cos(message.angles[hit]), np.sin(message.angles[hit])])
        ends = transform_points(relative, ranges[hit, None] * ends)
        angles[hit] = np.arctan2(ends[:, 1], ends[:, 0])
        new_ranges[hit] = np.hypot(ends[:, 0], ends[:, 1])
    return LidarScan(message.robot_id, message.stamp, angles, new_ranges, message.range_max_m)
