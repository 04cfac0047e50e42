"""``acslam run --record``: a simulated run as a rosbag2 in MCAP storage, for Foxglove,
RViz (through ``ros2 bag play``) and ``acslam slam rosbag``.

Per robot namespace ``robot_<i>`` (:func:`acslam.runner.robot_name`):

- ``scan`` (``sensor_msgs/LaserScan``, frame ``base_scan``),
- ``odom`` (``nav_msgs/Odometry``, ``odom -> base_footprint``): the robot's cumulative
  dead-reckoned pose, starting at its start pose at t = 0 (that first sample is written
  too, so a replay starts where the run's SLAM started: the odom frame is the map frame
  at the start),
- ``landmarks`` (``sensor_msgs/PointCloud2``, x y z in ``base_footprint``),
- ``tf``: ``odom -> base_footprint`` with every odometry sample, and ``map -> odom`` every
  server step, the correction that puts the base where SLAM estimates it
  (map_T_base * odom_T_base^-1, REP 105),
- ``tf_static``: ``base_footprint -> base_scan``, the identity (the simulated laser sits
  at the base's centre), transient local,
- ``cmd_vel`` (``geometry_msgs/Twist``), the server's command of every step,
- ``ground_truth`` (``nav_msgs/Odometry`` in frame ``world``), written when the run ends,

and for the team ``/map`` (``nav_msgs/OccupancyGrid``, transient local, cropped to its
known cells) every :data:`MAP_PERIOD_S` while it changes, and at the end. The frames of
every robot are named alike, each robot's transforms being on its own ``tf`` topics
(remap ``/tf`` to ``/robot_<i>/tf`` in RViz to follow one robot).

Stamps are simulated seconds. Only what the server received is recorded, as it received
it, so the bag replays to the run's own trajectories. A scan's ``range_min`` is 0 and its
``range_max`` covers its farthest return: the simulated LiDAR's noise carries returns a
little past its nominal range, which REP 117 would otherwise read as no return.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from acslam.geometry import between, compose
from acslam.messages import LandmarkObservations, LidarScan, OdometryIncrement, RobotMessage
from acslam.pipeline.snapshot import Snapshot
from acslam.ros2 import convert, wire
from acslam.ros2.bag import BagWriter
from acslam.ros2.source import Ros2Topics, resolve
from acslam.runner import TruthLog, robot_name
from acslam.scenario import Scenario

MAP_PERIOD_S = 5.0
MAP_FRAME = "map"
ODOM_FRAME = "odom"
BASE_FRAME = "base_footprint"
LASER_FRAME = "base_scan"
WORLD_FRAME = "world"


class BagRecorder:
    """Records a run through its hooks: :meth:`on_step` every server step,
    :meth:`on_finish` with the ground truth at the end (which writes the file)."""

    def __init__(
        self,
        path: str | Path,
        scenario: Scenario,
        distro: str = wire.DEFAULT_DISTRO,
        map_period_s: float = MAP_PERIOD_S,
    ) -> None:
        self.distro = distro
        self.map_period_s = map_period_s
        self.spec = scenario.world.spec
        self._writer = BagWriter(path, distro)
        topics = Ros2Topics()
        self._topics = [
            {
                kind: resolve(robot_name(i), getattr(topics, kind))
                for kind in (
                    "scan",
                    "odom",
                    "landmarks",
                    "tf",
                    "tf_static",
                    "cmd_vel",
                    "ground_truth",
                )
            }
            for i in range(scenario.robot_count)
        ]
        self._map_topic = topics.map
        self._poses = [np.array(start, dtype=float) for start in scenario.starts]
        self._last: Snapshot | None = None
        self._map_version = -1
        self._next_map_s = 0.0
        self._closed = False
        for robot, start in enumerate(self._poses):
            mount = convert.tf_message([(BASE_FRAME, LASER_FRAME, 0.0, np.zeros(3))], distro)
            self._writer.write(self._topics[robot]["tf_static"], mount, 0.0, latched=True)
            self._odometry(robot, 0.0, start, 0.0, 0.0)

    def on_step(self, snapshot: Snapshot, messages: list[RobotMessage]) -> None:
        """The messages the server received this step, and what it decided."""
        for message in messages:
            if isinstance(message, OdometryIncrement):
                robot = message.robot_id
                self._poses[robot] = compose(self._poses[robot], message.delta)
                dt_s = message.stamp - message.start_stamp
                v, omega = (message.dx / dt_s, message.dtheta / dt_s) if dt_s > 0 else (0.0, 0.0)
                self._odometry(robot, message.stamp, self._poses[robot], v, omega)
            elif isinstance(message, LidarScan):
                self._scan(message)
            elif isinstance(message, LandmarkObservations):
                cloud = convert.point_cloud_msg(
                    message.points, message.stamp, BASE_FRAME, self.distro
                )
                self._write(message.robot_id, "landmarks", cloud, message.stamp)
        now_s = snapshot.time_s
        for command in snapshot.commands:
            twist = convert.twist_msg(command.v, command.omega, self.distro)
            self._write(command.robot_id, "cmd_vel", twist, now_s)
        for robot, map_to_base in enumerate(snapshot.poses):
            map_to_odom = compose(map_to_base, between(self._poses[robot], np.zeros(3)))
            transform = convert.tf_message(
                [(MAP_FRAME, ODOM_FRAME, now_s, map_to_odom)], self.distro
            )
            self._write(robot, "tf", transform, now_s)
        self._last = snapshot
        if now_s >= self._next_map_s:
            self._map(snapshot)
            self._next_map_s = now_s + self.map_period_s

    def on_finish(self, truth: TruthLog) -> None:
        """The ground truth and the final map; then the file is complete."""
        for robot, rows in enumerate(truth.trajectories):
            for stamp_s, *pose in rows:
                odometry = convert.odometry_msg(
                    stamp_s, pose, 0.0, 0.0, WORLD_FRAME, BASE_FRAME, self.distro
                )
                self._write(robot, "ground_truth", odometry, stamp_s)
        if self._last is not None:
            self._map(self._last)
        self.close()

    def close(self) -> None:
        """Write the file (once), whatever has been recorded."""
        if not self._closed:
            self._closed = True
            self._writer.close()

    # ------------------------------------------------------------------ internals

    def _write(self, robot: int, kind: str, message: object, stamp_s: float) -> None:
        self._writer.write(self._topics[robot][kind], message, stamp_s)

    def _odometry(
        self, robot: int, stamp_s: float, pose: np.ndarray, v_mps: float, omega_radps: float
    ) -> None:
        odometry = convert.odometry_msg(
            stamp_s, pose, v_mps, omega_radps, ODOM_FRAME, BASE_FRAME, self.distro
        )
        self._write(robot, "odom", odometry, stamp_s)
        transform = convert.tf_message([(ODOM_FRAME, BASE_FRAME, stamp_s, pose)], self.distro)
        self._write(robot, "tf", transform, stamp_s)

    def _scan(self, scan: LidarScan) -> None:
        returns = scan.ranges[np.isfinite(scan.ranges)]
        range_max_m = max(scan.range_max_m, float(returns.max()) if len(returns) else 0.0)
        reaching = LidarScan(scan.robot_id, scan.stamp, scan.angles, scan.ranges, range_max_m)
        message = convert.laser_scan_msg(reaching, scan.stamp, LASER_FRAME, 0.0, self.distro)
        self._write(scan.robot_id, "scan", message, scan.stamp)

    def _map(self, snapshot: Snapshot) -> None:
        """The team map, unless it has not changed since the last one written."""
        if snapshot.map.version == self._map_version:
            return
        values = snapshot.map.occupancy_values()
        grid = convert.known_map_msg(values, self.spec, snapshot.time_s, MAP_FRAME, self.distro)
        self._writer.write(self._map_topic, grid, snapshot.time_s, latched=True)
        self._map_version = snapshot.map.version
