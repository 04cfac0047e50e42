"""Simulated 2D LiDAR: exact ray casting in the occupancy grid plus the other robots.

The thesis traces beams with Bresenham lines; we use the Amanatides-Woo grid traversal
(DDA) instead, which visits exactly the cells a real ray crosses (Bresenham can step
diagonally past a corner a ray clips, and skip a cell it crosses) and gives the exact
distance to the boundary of the first occupied cell rather than a cell-quantised one.
Other robots are discs intersected analytically, which is what "adding their shapes to
the map" approximates; so are a world's round obstacles (``World.discs``: plants), which
the grid holds only as staircases of cells.

Beam angles are in the robot frame (LiDAR at the robot centre, x forward): for a full
circle, ``angle_k = -pi + k * 2 pi / beams`` (no duplicate beam at +-pi); for a narrower
field of view, ``beams`` angles evenly from ``-fov/2`` to ``+fov/2`` inclusive (one beam:
straight ahead).

Noise: each beam is cast along its nominal angle plus N(0, angle_noise_std^2) but
reported at the nominal angle (the sensor's angle error), and the range gets
N(0, sigma(r)^2) with sigma(r) = range_noise_std_m + range_noise_rel * r. Whether a beam
returns is decided on the true range: beyond range_max_m it is ``inf`` (no return: free
space as far as the sensor reaches); closer than range_min_m it is 0, the invalid reading
real LiDAR drivers report (the space along it is unknown, not free). A noisy range is
clamped at 0.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from acslam.config import LidarConfig
from acslam.messages import LidarScan
from acslam.worlds.world import World


@numba.njit(cache=True, inline="always")
def _first_boundary(cell: int, direction: float) -> tuple[int, int]:
    """Along one axis: the cell step (+-1, or 0 for a ray parallel to the axis) and the
    index of the first cell boundary the ray crosses."""
    if direction > 0.0:
        return 1, cell + 1
    if direction < 0.0:
        return -1, cell
    return 0, 0


@numba.njit(cache=True, inline="always")
def _crossing_m(
    origin_m: float, boundary: int, resolution_m: float, start_m: float, direction: float
) -> float:
    """Distance along the ray to the boundary ``boundary`` of one axis (inf if parallel)."""
    if direction == 0.0:
        return math.inf
    return (origin_m + boundary * resolution_m - start_m) / direction


@numba.njit(cache=True)
def grid_ray_m(
    occupied: np.ndarray,
    origin_x_m: float,
    origin_y_m: float,
    resolution_m: float,
    px_m: float,
    py_m: float,
    dir_x: float,
    dir_y: float,
    max_range_m: float,
) -> float:
    """Distance from (px, py) along the unit direction to the first occupied cell.

    ``inf`` if none is entered within ``max_range_m``; 0 if the start cell is occupied.
    Cells outside the grid count as occupied (the border is a wall, as in
    :attr:`World.clearance_m`).
    """
    rows, cols = occupied.shape
    col = math.floor((px_m - origin_x_m) / resolution_m)
    row = math.floor((py_m - origin_y_m) / resolution_m)
    if row < 0 or row >= rows or col < 0 or col >= cols or occupied[row, col]:
        return 0.0
    # Each crossing distance is computed from its boundary index, not accumulated, so
    # ranges carry no drift over long rays.
    step_col, boundary_col = _first_boundary(col, dir_x)
    step_row, boundary_row = _first_boundary(row, dir_y)
    t_x = _crossing_m(origin_x_m, boundary_col, resolution_m, px_m, dir_x)
    t_y = _crossing_m(origin_y_m, boundary_row, resolution_m, py_m, dir_y)
    while True:
        if t_x < t_y:
            t = t_x
            col += step_col
            boundary_col += step_col
            t_x = _crossing_m(origin_x_m, boundary_col, resolution_m, px_m, dir_x)
        else:
            t = t_y
            row += step_row
            boundary_row += step_row
            t_y = _crossing_m(origin_y_m, boundary_row, resolution_m, py_m, dir_y)
        if t > max_range_m:
            return math.inf
        if row < 0 or row >= rows or col < 0 or col >= cols or occupied[row, col]:
            return max(t, 0.0)


@numba.njit(cache=True)
def _ray_disc_m(
    px_m: float, py_m: float, dir_x: float, dir_y: float, cx_m: float, cy_m: float, r_m: float
) -> float:
    """Distance along the unit ray to a disc's edge; ``inf`` if missed or started inside."""
    mx = px_m - cx_m
    my = py_m - cy_m
    c = mx * mx + my * my - r_m * r_m
    if c <= 0.0:
        return math.inf
    b = mx * dir_x + my * dir_y
    disc = b * b - c
    if disc < 0.0 or b > 0.0:
        return math.inf
    return -b - math.sqrt(disc)


@numba.njit(cache=True)
def cast_scan(
    occupied: np.ndarray,
    origin_x_m: float,
    origin_y_m: float,
    resolution_m: float,
    pose_x_m: float,
    pose_y_m: float,
    pose_theta_rad: float,
    beam_angles_rad: np.ndarray,
    angle_normals: np.ndarray,
    range_normals: np.ndarray,
    discs: np.ndarray,
    skip_disc: int,
    config_values: np.ndarray,
) -> np.ndarray:
    """Ranges of one scan; ``discs`` is (M, 3) ``[x, y, radius]``, row ``skip_disc`` ignored.

    ``config_values`` = [range_min, range_max, range_noise_std, range_noise_rel,
    angle_noise_std]; the normals are standard-normal draws, one per beam.
    """
    range_min_m = config_values[0]
    range_max_m = config_values[1]
    noise_std_m = config_values[2]
    noise_rel = config_values[3]
    angle_std_rad = config_values[4]
    n = beam_angles_rad.shape[0]
    out = np.empty(n)
    for k in range(n):
        a = pose_theta_rad + beam_angles_rad[k] + angle_std_rad * angle_normals[k]
        dx = math.cos(a)
        dy = math.sin(a)
        r = grid_ray_m(
            occupied, origin_x_m, origin_y_m, resolution_m, pose_x_m, pose_y_m, dx, dy, range_max_m
        )
        for j in range(discs.shape[0]):
            if j != skip_disc:
                rd = _ray_disc_m(pose_x_m, pose_y_m, dx, dy, discs[j, 0], discs[j, 1], discs[j, 2])
                if rd < r:
                    r = rd
        if r > range_max_m:
            out[k] = math.inf
        elif r < range_min_m:
            out[k] = 0.0
        else:
            out[k] = max(0.0, r + (noise_std_m + noise_rel * r) * range_normals[k])
    return out


def beam_angles(config: LidarConfig) -> np.ndarray:
    """Nominal beam angles in the robot frame (see the module docstring), read-only."""
    if config.fov_rad >= 2.0 * math.pi - 1e-12:
        angles = -math.pi + np.arange(config.beams) * (2.0 * math.pi / config.beams)
    elif config.beams == 1:
        angles = np.zeros(1)
    else:
        angles = np.linspace(-0.5 * config.fov_rad, 0.5 * config.fov_rad, config.beams)
    angles.flags.writeable = False
    return angles


class LidarSensor:
    """One robot's LiDAR: its beam layout, noise stream and the world grid."""

    def __init__(self, config: LidarConfig, world: World, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        self._occupied = np.ascontiguousarray(world.lidar_grid)
        self._discs = np.ascontiguousarray(world.discs, dtype=np.float64)
        spec = world.spec
        self._grid = (spec.origin_x_m, spec.origin_y_m, spec.resolution_m)
        self.angles_rad = beam_angles(config)
        self._config_values = np.array(
            [
                config.range_min_m,
                config.range_max_m,
                config.range_noise_std_m,
                config.range_noise_rel,
                config.angle_noise_std_rad,
            ]
        )

    def scan(
        self,
        robot_id: int,
        stamp_s: float,
        pose: tuple[float, float, float],
        discs: np.ndarray,
        skip_disc: int,
    ) -> LidarScan:
        """A scan from ``pose``, seeing the robots ``discs`` except row ``skip_disc``, and
        the world's round obstacles within range."""
        normals = self._rng.standard_normal((2, self.angles_rad.shape[0]))
        if len(self._discs):
            reach = self.config.range_max_m + self._discs[:, 2]
            near = self._discs[
                np.hypot(self._discs[:, 0] - pose[0], self._discs[:, 1] - pose[1]) <= reach
            ]
            discs = np.concatenate([discs.reshape(-1, 3), near])
        ranges = cast_scan(
            self._occupied,
            *self._grid,
            *pose,
            self.angles_rad,
            normals[0],
            normals[1],
            discs,
            skip_disc,
            self._config_values,
        )
        return LidarScan(
            robot_id=robot_id,
            stamp=stamp_s,
            angles=self.angles_rad,
            ranges=ranges,
            range_max_m=self.config.range_max_m,
        )
