"""``acslam robot --ros2``: one simulated robot that speaks ROS 2 as a real one would.

It publishes, under its namespace, ``odom`` (``nav_msgs/Odometry``, its own dead-reckoned
pose in its ``odom`` frame, which starts where the robot starts, REP 105), ``tf``
(``odom -> base_footprint``), ``tf_static`` (``base_footprint -> base_scan``: the
simulated LiDAR sits at the centre), ``scan`` (``sensor_msgs/LaserScan``) and
``landmarks`` (``sensor_msgs/PointCloud2``), and drives by ``cmd_vel``. Like a real robot
it publishes from the moment it starts, whether or not a server listens, and stands
still when no command comes.

``ground_truth`` (``nav_msgs/Odometry`` in the world frame) is the simulation's side
channel, as Gazebo's ground-truth plugin publishes it: the other simulated robots place
this one from it, so their LiDAR sees it. The server reads it only for the evaluation.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from acslam.distributed.robot_node import RobotAgent, RobotOptions
from acslam.errors import TransportError
from acslam.geometry import compose
from acslam.messages import (
    LandmarkObservations,
    LidarScan,
    OdometryIncrement,
    RobotMessage,
    VelocityCommand,
)
from acslam.ros2 import convert
from acslam.ros2.node import Ros2Node, Ros2Options, open_ros2_session
from acslam.ros2.source import SENSOR_QOS, TF_STATIC_QOS, Ros2Topics, cmd_vel_type, resolve
from acslam.scenario import Scenario
from acslam.text import plural
from acslam.transport import CommandInbox
from acslam.transport.codec import StatusBeacon, TruthBatch

BASE_FRAME = "base_footprint"
LASER_FRAME = "base_scan"
ODOM_FRAME = "odom"
LASER_RANGE_MIN_M = 0.12  # the LDS-02's minimum range
ROBOT_NODE_NAME = "turtlebot3_node"  # as TurtleBot3's driver node is named


class Ros2RobotEndpoint:
    """A simulated robot's ROS 2 topics as the robot agent's link
    (:class:`~acslam.distributed.robot_node.RobotLink`)."""

    def __init__(
        self,
        node: Ros2Node,
        robot_id: int,
        namespaces: list[str],
        topics: Ros2Topics | None = None,
    ) -> None:
        self.node = node
        self.robot_id = robot_id
        self.namespace = namespaces[robot_id]
        self.topics = topics or Ros2Topics()
        self.clock_origin_s = time.time()
        self._lock = threading.Lock()
        self._pose = np.zeros(3)  # in the odom frame
        self._velocity = (0.0, 0.0)
        self._commands = CommandInbox()
        self._others: dict[int, np.ndarray] = {}
        t, ns = self.topics, self.namespace
        self._cmd_vel_type = cmd_vel_type(node.options.distro, self.topics.cmd_vel_stamped)
        self._publishers = {
            "odom": node.publisher(resolve(ns, t.odom), "nav_msgs/msg/Odometry"),
            "scan": node.publisher(resolve(ns, t.scan), "sensor_msgs/msg/LaserScan", SENSOR_QOS),
            "landmarks": node.publisher(resolve(ns, t.landmarks), "sensor_msgs/msg/PointCloud2"),
            "tf": node.publisher(resolve(ns, t.tf), "tf2_msgs/msg/TFMessage"),
            "tf_static": node.publisher(
                resolve(ns, t.tf_static), "tf2_msgs/msg/TFMessage", TF_STATIC_QOS
            ),
            "truth": node.publisher(resolve(ns, t.ground_truth), "nav_msgs/msg/Odometry"),
        }
        node.subscribe(resolve(ns, t.cmd_vel), self._cmd_vel_type, self._on_command)
        for other, other_ns in enumerate(namespaces):
            if other != robot_id:
                node.subscribe(
                    resolve(other_ns, t.ground_truth),
                    "nav_msgs/msg/Odometry",
                    lambda message, other=other: self._on_truth(other, message),
                )
        static = [(BASE_FRAME, LASER_FRAME, self.clock_origin_s, np.zeros(3))]
        self._publishers["tf_static"].put(convert.tf_message(static, self._distro))

    @property
    def _distro(self) -> str:
        return self.node.options.distro

    def _ros_stamp(self, stamp_s: float) -> float:
        return self.clock_origin_s + stamp_s

    # ------------------------------------------------------------------ callbacks

    def _on_command(self, message: Any) -> None:
        v, omega = convert.twist_command(message)
        self._commands.put(VelocityCommand(self.robot_id, 0.0, v, omega))

    def _on_truth(self, robot: int, message: Any) -> None:
        _, pose, _, _ = convert.odometry_pose(message)
        with self._lock:
            self._others[robot] = pose

    # ------------------------------------------------------------------ the agent's link

    def publish(self, message: RobotMessage) -> None:
        stamp_s = self._ros_stamp(message.stamp)
        if isinstance(message, OdometryIncrement):
            self._pose = compose(self._pose, message.delta)
            dt_s = max(message.stamp - message.start_stamp, 1e-9)
            v, omega = float(np.hypot(message.dx, message.dy)) / dt_s, message.dtheta / dt_s
            odom = convert.odometry_msg(
                stamp_s, self._pose, v, omega, ODOM_FRAME, BASE_FRAME, self._distro
            )
            self._publishers["odom"].put(odom)
            transform = [(ODOM_FRAME, BASE_FRAME, stamp_s, self._pose)]
            self._publishers["tf"].put(convert.tf_message(transform, self._distro))
        elif isinstance(message, LidarScan):
            scan = convert.laser_scan_msg(
                message, stamp_s, LASER_FRAME, LASER_RANGE_MIN_M, self._distro
            )
            self._publishers["scan"].put(scan)
        elif isinstance(message, LandmarkObservations):
            self._publishers["landmarks"].put(
                convert.point_cloud_msg(message.points, stamp_s, BASE_FRAME, self._distro)
            )

    def flush(self) -> None:
        """Nothing is held back (no injected latency on the ROS 2 path)."""

    def heartbeat(self, stamp: float) -> None:
        """ROS 2 robots send no heartbeat: the server watches their odometry."""

    def publish_truth(self, batch: TruthBatch) -> None:
        stamp_s = self._ros_stamp(float(batch.stamps[-1]))
        pose = batch.poses[-1]
        truth = convert.odometry_msg(stamp_s, pose, 0.0, 0.0, "world", BASE_FRAME, self._distro)
        self._publishers["truth"].put(truth)

    def receive_commands(self) -> list[VelocityCommand]:
        return self._commands.take()

    def status(self) -> tuple[float, StatusBeacon] | None:
        """When a command last came: the only sign of a server a ROS robot gets."""
        last_s = self._commands.last_s
        return None if last_s is None else (last_s, StatusBeacon(0.0, False, ()))

    def other_poses(self) -> dict[int, np.ndarray]:
        with self._lock:
            return dict(self._others)

    def stats_summary(self) -> dict:
        stats = self.node.statistics()
        return {
            "clock_origin_s": self.clock_origin_s,
            "messages": dict(stats.messages),
            "bytes": dict(stats.bytes),
            "dropped": dict(stats.dropped),
        }


def run_ros2_robot(
    scenario: Scenario,
    robot_id: int,
    namespaces: list[str],
    connect: list[str],
    max_time_s: float,
    *,
    options: RobotOptions,
    ros2: Ros2Options,
    topics: Ros2Topics | None = None,
) -> str:
    """Drive simulated robot ``robot_id`` over ROS 2 until ``max_time_s`` or a stopping
    signal (:mod:`acslam.stop`; reason ``terminated``, ground-truth log written); returns
    why it stopped."""
    if not 0 <= robot_id < scenario.robot_count:
        raise TransportError(
            f"--id: robot {robot_id} does not exist, the team has {scenario.robot_count}"
        )
    if len(namespaces) != scenario.robot_count:
        raise TransportError(
            f"--namespaces: {plural(len(namespaces), 'name')} for a team of {scenario.robot_count}"
        )
    config = scenario.config
    sim = scenario.simulator()
    session = open_ros2_session(connect=connect)
    node = Ros2Node(session, ROBOT_NODE_NAME, "/" + namespaces[robot_id].strip("/"), ros2)
    try:
        link = Ros2RobotEndpoint(node, robot_id, namespaces, topics)
        period_s = config.algorithms.planning.control_period_s
        agent = RobotAgent(sim, link, robot_id, options, config.sim.dt_s, period_s)
        return agent.run(max_time_s, wait_for_server=False)
    finally:
        node.close()
        session.close()
