"""Simulated landmark camera (thesis §4.9): noisy 3D landmark points in the robot frame.

A landmark is seen when its horizontal distance lies in [range_min_m, range_max_m], its
bearing within +-fov/2, and no wall blocks the line of sight. Landmarks stand next to
walls, so the occlusion ray stops ``OCCLUSION_STOP_SHORT_CELLS`` cells before the
landmark: the wall it is attached to does not hide it. Points are in the robot frame
(x forward, y left, z up, origin on the ground under the robot centre) with
N(0, noise_std_m^2) per axis. Other robots do not occlude landmarks.

The message is shuffled into a random order so the point order does not leak landmark
identities; the true indices, in message order, go only to the ground-truth channel.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from acslam.config import CameraConfig
from acslam.messages import LandmarkObservations
from acslam.sim.lidar import grid_ray_m
from acslam.worlds.world import World

OCCLUSION_STOP_SHORT_CELLS = 1.5


@numba.njit(cache=True)
def _lines_of_sight_clear(
    occupied: np.ndarray,
    grid: tuple[float, float, float],
    sensor_xy_m: tuple[float, float],
    targets_xy_m: np.ndarray,
    stop_short_m: float,
) -> np.ndarray:
    """For each (M, 2) target, whether the grid ray to it is free up to ``stop_short_m``.

    ``grid`` is (origin x, origin y, resolution) in metres.
    """
    origin_x_m, origin_y_m, resolution_m = grid
    px_m, py_m = sensor_xy_m
    n = targets_xy_m.shape[0]
    clear = np.empty(n, dtype=np.bool_)
    for k in range(n):
        dx = targets_xy_m[k, 0] - px_m
        dy = targets_xy_m[k, 1] - py_m
        dist = math.sqrt(dx * dx + dy * dy)
        reach = dist - stop_short_m
        if reach <= 0.0:
            clear[k] = True
            continue
        hit = grid_ray_m(
            occupied, origin_x_m, origin_y_m, resolution_m, px_m, py_m, dx / dist, dy / dist, reach
        )
        clear[k] = hit > reach
    return clear


class CameraSensor:
    """One robot's landmark camera: the landmark set, the grid and its noise stream."""

    def __init__(
        self,
        config: CameraConfig,
        world: World,
        landmarks_xyz_m: np.ndarray,
        rng: np.random.Generator,
    ) -> None:
        self.config = config
        self._rng = rng
        self._landmarks = np.ascontiguousarray(landmarks_xyz_m, dtype=float).reshape(-1, 3)
        self._occupied = np.ascontiguousarray(world.occupied)
        spec = world.spec
        self._grid = (spec.origin_x_m, spec.origin_y_m, spec.resolution_m)
        self._stop_short_m = OCCLUSION_STOP_SHORT_CELLS * spec.resolution_m

    def observe(
        self, robot_id: int, stamp_s: float, pose: tuple[float, float, float]
    ) -> tuple[LandmarkObservations, np.ndarray]:
        """The message from ``pose`` and, for ground truth only, the landmark indices."""
        x, y, theta = pose
        c, s = math.cos(theta), math.sin(theta)
        rel_x = self._landmarks[:, 0] - x
        rel_y = self._landmarks[:, 1] - y
        forward = c * rel_x + s * rel_y
        left = -s * rel_x + c * rel_y
        dist = np.hypot(forward, left)
        bearing = np.arctan2(left, forward)
        cfg = self.config
        candidates = np.flatnonzero(
            (dist >= cfg.range_min_m)
            & (dist <= cfg.range_max_m)
            & (np.abs(bearing) <= 0.5 * cfg.fov_rad)
        )
        if candidates.size:
            clear = _lines_of_sight_clear(
                self._occupied,
                self._grid,
                (x, y),
                np.ascontiguousarray(self._landmarks[candidates, :2]),
                self._stop_short_m,
            )
            candidates = candidates[clear]
        ids = self._rng.permutation(candidates)
        points = np.stack([forward[ids], left[ids], self._landmarks[ids, 2]], axis=1)
        points += cfg.noise_std_m * self._rng.standard_normal(points.shape)
        return LandmarkObservations(robot_id=robot_id, stamp=stamp_s, points=points), ids
