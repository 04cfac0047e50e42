"""The robot <-> server contract: the only data that crosses between them.

Every message carries the robot index and a timestamp in simulated (or log) seconds and is
validated when it is built, so a NaN or a malformed array is rejected where it is made,
not deep inside the server. Ground truth never travels in these messages.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from acslam.errors import MessageError


def _check_header(kind: str, robot_id: int, stamp: float) -> None:
    if not isinstance(robot_id, (int, np.integer)) or robot_id < 0:
        raise MessageError(f"{kind}.robot_id: must be a non-negative integer, got {robot_id!r}")
    if not math.isfinite(stamp):
        raise MessageError(f"{kind}.stamp: must be finite, got {stamp!r}")


def _check_finite(kind: str, name: str, value: float | np.ndarray) -> None:
    finite = math.isfinite(value) if isinstance(value, (int, float)) else np.isfinite(value).all()
    if not finite:
        raise MessageError(f"{kind}.{name}: must be finite (no NaN or inf)")


@dataclass(frozen=True)
class OdometryIncrement:
    """Relative motion measured by odometry/IMU between ``start_stamp`` and ``stamp``.

    ``[dx, dy, dtheta]`` is the end pose expressed in the frame of the start pose
    (metres, radians), as integrated by the robot's own noisy estimate.
    """

    robot_id: int
    stamp: float
    start_stamp: float
    dx: float
    dy: float
    dtheta: float

    def __post_init__(self) -> None:
        _check_header("OdometryIncrement", self.robot_id, self.stamp)
        for name in ("start_stamp", "dx", "dy", "dtheta"):
            _check_finite("OdometryIncrement", name, getattr(self, name))
        if self.start_stamp > self.stamp:
            raise MessageError("OdometryIncrement.start_stamp: must not be after stamp")

    @property
    def delta(self) -> np.ndarray:
        return np.array([self.dx, self.dy, self.dtheta])


@dataclass(frozen=True)
class LidarScan:
    """One 2D LiDAR sweep in the robot frame.

    ``angles`` (rad) and ``ranges`` (m) have shape (N,) and are read-only. A beam with
    no return within ``range_max_m`` has range ``inf`` (free as far as the sensor
    reaches); a range of 0 is an invalid reading (e.g. an object closer than the sensor's
    minimum range), which says nothing about the space along the beam. NaN and negative
    ranges are rejected.
    """

    robot_id: int
    stamp: float
    angles: np.ndarray
    ranges: np.ndarray
    range_max_m: float

    def __post_init__(self) -> None:
        _check_header("LidarScan", self.robot_id, self.stamp)
        angles = np.asarray(self.angles, dtype=float)
        ranges = np.asarray(self.ranges, dtype=float)
        if angles.ndim != 1 or angles.shape != ranges.shape:
            raise MessageError("LidarScan.ranges: angles and ranges must be (N,) of equal length")
        _check_finite("LidarScan", "angles", angles)
        if np.isnan(ranges).any() or (ranges < 0).any() or np.isneginf(ranges).any():
            raise MessageError("LidarScan.ranges: must be >= 0 or +inf (no return), never NaN")
        if not (math.isfinite(self.range_max_m) and self.range_max_m > 0):
            raise MessageError("LidarScan.range_max_m: must be finite and > 0")
        # The message owns read-only copies: the localizer's scan store and the map
        # share them instead of copying each scan again.
        for name, values in (("angles", angles), ("ranges", ranges)):
            owned = np.array(values)
            owned.flags.writeable = False
            object.__setattr__(self, name, owned)


@dataclass(frozen=True)
class LandmarkObservations:
    """3D landmark points seen by the camera, in the robot frame (m).

    ``points`` has shape (N, 3); ``descriptors`` (N, D) uint8 is optional (ORB features
    carry them, simulated landmarks do not). ``ids`` (N,) are identities the sensor
    recognised itself (fiducials, barcodes): given, they replace data association. N may
    be 0.
    """

    robot_id: int
    stamp: float
    points: np.ndarray
    descriptors: np.ndarray | None = field(default=None)
    ids: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        _check_header("LandmarkObservations", self.robot_id, self.stamp)
        points = np.asarray(self.points, dtype=float)
        if points.size == 0:
            points = points.reshape(0, 3)
        if points.ndim != 2 or points.shape[1] != 3:
            raise MessageError("LandmarkObservations.points: must have shape (N, 3)")
        _check_finite("LandmarkObservations", "points", points)
        if self.descriptors is not None and len(self.descriptors) != len(points):
            raise MessageError("LandmarkObservations.descriptors: one row per point required")
        if self.ids is not None:
            ids = np.asarray(self.ids)
            if ids.shape != (len(points),) or not np.issubdtype(ids.dtype, np.integer):
                raise MessageError("LandmarkObservations.ids: one integer per point required")
            object.__setattr__(self, "ids", ids)
        object.__setattr__(self, "points", points)


@dataclass(frozen=True)
class RobotSighting:
    """Robot ``robot_id`` saw robot ``observed_id`` at ``point`` ``[x, y, z]`` (metres, in
    the observer's frame). The identity comes from a signal of the seen robot's own (a
    marker on it, as MRCLAM's barcodes), so no association is needed."""

    robot_id: int
    stamp: float
    observed_id: int
    point: np.ndarray

    def __post_init__(self) -> None:
        _check_header("RobotSighting", self.robot_id, self.stamp)
        _check_header("RobotSighting", self.observed_id, self.stamp)
        if self.observed_id == self.robot_id:
            raise MessageError("RobotSighting.observed_id: a robot cannot see itself")
        point = np.asarray(self.point, dtype=float)
        if point.shape != (3,):
            raise MessageError("RobotSighting.point: must have shape (3,)")
        _check_finite("RobotSighting", "point", point)
        object.__setattr__(self, "point", point)


@dataclass(frozen=True)
class VelocityCommand:
    """Commanded linear (m/s) and angular (rad/s) velocity for one robot."""

    robot_id: int
    stamp: float
    v: float
    omega: float

    def __post_init__(self) -> None:
        _check_header("VelocityCommand", self.robot_id, self.stamp)
        _check_finite("VelocityCommand", "v", self.v)
        _check_finite("VelocityCommand", "omega", self.omega)


RobotMessage = OdometryIncrement | LidarScan | LandmarkObservations | RobotSighting
