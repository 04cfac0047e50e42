"""The multi-robot simulator of thesis §4.9, stepped synchronously on a fixed clock.

The thesis runs one thread per robot and sensor; here one :meth:`Simulator.step`
advances every robot by ``dt_s`` and then fires each sensor whose period has elapsed,
which gives the same data deterministically (same seed -> same messages).

Decisions worth knowing:

* Motion follows eq. 4.72 exactly while free. Each step's straight Euler segment is
  checked in substeps no longer than half a grid cell, so no robot tunnels through a
  one-cell wall. A substep is refused when the robot disc would touch a wall
  (``world.clearance_at(x, y) < radius``, exact against the cell squares) or another
  robot (centre distance < 2 radius); the robot then stays at the last free position,
  its linear velocity becomes 0, and it still turns (a disc turning in place cannot collide).
* Collisions are counted per contact, not per step: a contact starts at a refusal and
  ends once the robot is ``CONTACT_RELEASE_CELLS`` grid cells clear of that wall or
  robot, so pushing against an obstacle counts once.
* Odometry integrates the velocity the robot actually had (the wheels stop at contact),
  i.e. the fraction of the step it really travelled, through its noise model. With all
  noise off, odometry equals the ground truth exactly, collisions included.
* Ground truth is only reachable through :attr:`Simulator.ground_truth`; the messages
  ``step`` returns carry none. Robots move in id order, each seeing the others' newest
  positions; sensors fire after all robots moved.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from acslam.config import RobotsConfig, SensorsConfig, SimConfig
from acslam.errors import ConfigError
from acslam.messages import RobotMessage, VelocityCommand
from acslam.schedule import is_due
from acslam.seeding import Stream, rng
from acslam.sim.camera import CameraSensor
from acslam.sim.kinematics import limit_command, step_pose
from acslam.sim.lidar import LidarSensor
from acslam.sim.odometry import OdometryModel
from acslam.worlds.world import World

CONTACT_RELEASE_CELLS = 2.0


@dataclass
class _Robot:
    """Mutable true state of one robot (plain floats: touched every step)."""

    x_m: float
    y_m: float
    theta_rad: float
    odometry: OdometryModel
    lidar: LidarSensor
    camera: CameraSensor
    v_mps: float = 0.0
    omega_radps: float = 0.0
    cmd_v_mps: float = 0.0
    cmd_omega_radps: float = 0.0
    wall_contact: bool = False
    robot_contacts: set[int] = field(default_factory=set)


@dataclass(frozen=True)
class CameraGroundTruth:
    """Which landmarks (indices into the landmark array, in message order) one camera
    message shows."""

    robot_id: int
    stamp: float
    landmark_ids: np.ndarray


class GroundTruth:
    """Evaluation-only view of the true state; never sent to the server.

    The trajectory is logged every simulation step, so every message stamp (all are
    step times) has a true pose row.
    """

    def __init__(self, starts: np.ndarray, landmarks: np.ndarray) -> None:
        self._trajectories: list[list[tuple[float, float, float, float]]] = [
            [(0.0, float(x), float(y), float(theta))] for x, y, theta in starts
        ]
        self._landmarks = landmarks
        self._landmarks.flags.writeable = False
        self._camera_log: list[CameraGroundTruth] = []
        self._camera_index: dict[tuple[int, float], np.ndarray] = {}
        self._collisions = np.zeros((len(starts), 2), dtype=np.int64)

    def poses(self) -> np.ndarray:
        """(N, 3) current true poses ``[x, y, theta]``."""
        return np.array([trajectory[-1][1:] for trajectory in self._trajectories])

    def trajectory(self, robot_id: int) -> np.ndarray:
        """(T, 4) ``[t, x, y, theta]`` of one robot, one row per step from t = 0."""
        return np.array(self._trajectories[robot_id])

    @property
    def landmarks(self) -> np.ndarray:
        """(L, 3) true landmark positions in the world frame (read-only)."""
        return self._landmarks

    @property
    def camera_log(self) -> list[CameraGroundTruth]:
        """One entry per camera message, in message order."""
        return list(self._camera_log)

    def observed_landmark_ids(self, robot_id: int, stamp: float) -> np.ndarray:
        """Landmark indices behind the points of one camera message, in the same order."""
        return self._camera_index[(robot_id, stamp)]

    @property
    def collisions(self) -> np.ndarray:
        """(N, 2) contact counts per robot: column 0 walls, column 1 other robots."""
        return self._collisions.copy()

    def _log_pose(self, robot_id: int, stamp: float, robot: _Robot) -> None:
        self._trajectories[robot_id].append((stamp, robot.x_m, robot.y_m, robot.theta_rad))

    def _log_camera(self, robot_id: int, stamp: float, ids: np.ndarray) -> None:
        ids.flags.writeable = False
        self._camera_log.append(CameraGroundTruth(robot_id, stamp, ids))
        self._camera_index[(robot_id, stamp)] = ids


class _Schedule:
    """Fires at the first step time >= the next due time, then moves it one period on."""

    def __init__(self, rate_hz: float) -> None:
        self.period_s = 1.0 / rate_hz
        self.next_due_s = self.period_s

    def due(self, time_s: float) -> bool:
        if not is_due(time_s, self.next_due_s):
            return False
        self.next_due_s += self.period_s
        return True


class Simulator:
    """Ground-truth motion of N robots in a world, and the messages their sensors send."""

    def __init__(
        self,
        world: World,
        starts: np.ndarray,
        landmarks: np.ndarray,
        robots: RobotsConfig,
        sensors: SensorsConfig,
        sim: SimConfig,
        seed: int,
    ) -> None:
        starts = np.array(starts, dtype=float).reshape(-1, 3)
        landmarks = np.array(landmarks, dtype=float).reshape(-1, 3)
        if not np.isfinite(starts).all():
            raise ConfigError(None, "robots.starts", "start poses must be finite")
        self.world = world
        self._limits = robots
        self._radius_m = robots.radius_m
        self._dt_s = sim.dt_s
        self._max_substep_m = 0.5 * world.spec.resolution_m
        self._release_m = CONTACT_RELEASE_CELLS * world.spec.resolution_m
        self._step_index = 0
        self._robots: list[_Robot] = []
        for i, (x, y, theta) in enumerate(starts):
            pose = (float(x), float(y), float(theta))
            self._check_start(i, pose)
            self._robots.append(
                _Robot(
                    *pose,
                    odometry=OdometryModel(
                        i, sensors.odometry, pose, sim.dt_s, rng(seed, Stream.ODOMETRY, i)
                    ),
                    lidar=LidarSensor(sensors.lidar, world, rng(seed, Stream.LIDAR, i)),
                    camera=CameraSensor(
                        sensors.camera, world, landmarks, rng(seed, Stream.CAMERA, i)
                    ),
                )
            )
        self._odometry_schedule = _Schedule(sensors.odometry.rate_hz)
        self._lidar_schedule = _Schedule(sensors.lidar.rate_hz)
        self._camera_schedule = _Schedule(sensors.camera.rate_hz)
        self._ground_truth = GroundTruth(starts, landmarks)

    @property
    def time_s(self) -> float:
        return self._step_index * self._dt_s

    @property
    def robot_count(self) -> int:
        return len(self._robots)

    def place_robot(self, robot_id: int, pose: tuple[float, float, float]) -> None:
        """Put a robot at ``[x, y, theta]``: a process that simulates one robot of a team
        places the others where their own processes report them."""
        robot = self._robots[robot_id]
        robot.x_m, robot.y_m, robot.theta_rad = pose

    @property
    def ground_truth(self) -> GroundTruth:
        """The evaluation interface; whatever drives the robots must not read it."""
        return self._ground_truth

    def step(
        self, commands: Mapping[int, VelocityCommand] | Iterable[VelocityCommand] = ()
    ) -> list[RobotMessage]:
        """Advance one ``dt_s``; robots without a new command keep their last one.

        Returns the messages of this step, ordered by robot id, then odometry, LiDAR,
        camera.
        """
        if isinstance(commands, Mapping):
            commands = commands.values()
        for command in commands:
            if not 0 <= command.robot_id < len(self._robots):
                raise ValueError(f"VelocityCommand.robot_id {command.robot_id}: no such robot")
            robot = self._robots[command.robot_id]
            robot.cmd_v_mps = command.v
            robot.cmd_omega_radps = command.omega
        self._step_index += 1
        now_s = self.time_s
        gt = self._ground_truth
        for i, robot in enumerate(self._robots):
            self._move(i, robot)
            gt._log_pose(i, now_s, robot)
        odometry_due = self._odometry_schedule.due(now_s)
        lidar_due = self._lidar_schedule.due(now_s)
        camera_due = self._camera_schedule.due(now_s)
        messages: list[RobotMessage] = []
        if not (odometry_due or lidar_due or camera_due):
            return messages
        discs = np.array([(r.x_m, r.y_m, self._radius_m) for r in self._robots])
        for i, robot in enumerate(self._robots):
            pose = (robot.x_m, robot.y_m, robot.theta_rad)
            if odometry_due:
                messages.append(robot.odometry.emit(now_s))
            if lidar_due:
                messages.append(robot.lidar.scan(i, now_s, pose, discs, i))
            if camera_due:
                observation, ids = robot.camera.observe(i, now_s, pose)
                messages.append(observation)
                gt._log_camera(i, now_s, ids)
        return messages

    def _move(self, i: int, robot: _Robot) -> None:
        """Advance robot ``i`` one step with collision checks, then its odometry."""
        dt_s = self._dt_s
        v, omega = limit_command(
            robot.cmd_v_mps,
            robot.cmd_omega_radps,
            robot.v_mps,
            robot.omega_radps,
            self._limits,
            dt_s,
        )
        x0, y0 = robot.x_m, robot.y_m
        x1, y1, theta1 = step_pose(x0, y0, robot.theta_rad, v, omega, dt_s)
        travelled = 1.0
        if v != 0.0:
            substeps = max(1, math.ceil(abs(v) * dt_s / self._max_substep_m))
            for k in range(1, substeps + 1):
                f = k / substeps
                x, y = (x1, y1) if k == substeps else (x0 + f * (x1 - x0), y0 + f * (y1 - y0))
                if self._blocked(i, robot, x, y):
                    travelled = (k - 1) / substeps
                    x1, y1 = x0 + travelled * (x1 - x0), y0 + travelled * (y1 - y0)
                    break
        robot.x_m, robot.y_m, robot.theta_rad = x1, y1, theta1
        robot.v_mps = v if travelled == 1.0 else 0.0
        robot.omega_radps = omega
        robot.odometry.step(travelled * v, omega)
        self._release_contacts(i, robot)

    def _blocked(self, i: int, robot: _Robot, x: float, y: float) -> bool:
        """Whether the disc at (x, y) touches something; starts contacts it makes."""
        radius = self._radius_m
        blocked = False
        if self.world.clearance_at(x, y) < radius:
            blocked = True
            if not robot.wall_contact:
                robot.wall_contact = True
                self._ground_truth._collisions[i, 0] += 1
        for j, other in enumerate(self._robots):
            if j != i and math.hypot(x - other.x_m, y - other.y_m) < 2.0 * radius:
                blocked = True
                if j not in robot.robot_contacts:
                    robot.robot_contacts.add(j)
                    self._ground_truth._collisions[i, 1] += 1
        return blocked

    def _release_contacts(self, i: int, robot: _Robot) -> None:
        """End contacts the robot has moved clearly away from."""
        if robot.wall_contact and (
            self.world.clearance_at(robot.x_m, robot.y_m) >= self._radius_m + self._release_m
        ):
            robot.wall_contact = False
        for j in list(robot.robot_contacts):
            other = self._robots[j]
            gap_m = math.hypot(robot.x_m - other.x_m, robot.y_m - other.y_m) - 2.0 * self._radius_m
            if gap_m >= self._release_m:
                robot.robot_contacts.discard(j)

    def _check_start(self, i: int, pose: tuple[float, float, float]) -> None:
        x, y, _ = pose
        if self.world.clearance_at(x, y) < self._radius_m:
            raise ConfigError(None, f"robots.starts[{i}]", "robot disc touches an obstacle")
        for j, other in enumerate(self._robots):
            if math.hypot(x - other.x_m, y - other.y_m) < 2.0 * self._radius_m:
                raise ConfigError(None, f"robots.starts[{i}]", f"robot overlaps robot {j}")
