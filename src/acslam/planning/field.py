"""What the local planners share: the robot state and a continuous distance field.

The distance field is the grid's ``distance_m`` (distance of each cell centre to the
nearest obstacle) interpolated bilinearly between cell centres, so the local planners see
a continuous clearance with a gradient for the FGP obstacle Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acslam.grid import GridSpec

NO_OBSTACLE_M = 1.0e3
"""Clearance used where the distance transform found no obstacle at all."""


@dataclass(frozen=True)
class RobotState:
    """Estimated pose (m, rad) and current velocity command (m/s, rad/s) of one robot."""

    x_m: float
    y_m: float
    theta_rad: float
    v_mps: float = 0.0
    omega_radps: float = 0.0

    @property
    def xy_m(self) -> np.ndarray:
        return np.array([self.x_m, self.y_m])


class DistanceField:
    """Bilinear interpolation of a per-cell distance field (m) and its gradient.

    Outside the band of cell centres the query is clamped onto the grid edge, where the
    gradient is zero.
    """

    def __init__(self, distance_m: np.ndarray, grid: GridSpec) -> None:
        if distance_m.shape != grid.shape:
            raise ValueError(f"distance field {distance_m.shape} does not match grid {grid.shape}")
        # No obstacle in the window makes the transform infinite; a finite cap keeps the
        # gradient 0 there instead of inf - inf = NaN, and is as good as infinite clearance.
        self.distance_m = np.minimum(np.asarray(distance_m, dtype=float), NO_OBSTACLE_M)
        self.grid = grid

    def _corners(self, xy_m: np.ndarray) -> tuple[np.ndarray, ...]:
        g = self.grid
        col = np.clip((xy_m[..., 0] - g.origin_x_m) / g.resolution_m - 0.5, 0.0, g.cols - 1.0)
        row = np.clip((xy_m[..., 1] - g.origin_y_m) / g.resolution_m - 0.5, 0.0, g.rows - 1.0)
        c0 = np.minimum(np.floor(col).astype(np.int64), max(g.cols - 2, 0))
        r0 = np.minimum(np.floor(row).astype(np.int64), max(g.rows - 2, 0))
        c1 = np.minimum(c0 + 1, g.cols - 1)
        r1 = np.minimum(r0 + 1, g.rows - 1)
        d = self.distance_m
        return col - c0, row - r0, d[r0, c0], d[r0, c1], d[r1, c0], d[r1, c1]

    def value(self, xy_m: np.ndarray) -> np.ndarray:
        """Distance (m) at (..., 2) world points."""
        fc, fr, d00, d01, d10, d11 = self._corners(np.asarray(xy_m, dtype=float))
        return (1 - fr) * ((1 - fc) * d00 + fc * d01) + fr * ((1 - fc) * d10 + fc * d11)

    def value_and_gradient(self, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) and its gradient ``[d/dx, d/dy]`` at (..., 2) world points."""
        xy_m = np.asarray(xy_m, dtype=float)
        fc, fr, d00, d01, d10, d11 = self._corners(xy_m)
        value = (1 - fr) * ((1 - fc) * d00 + fc * d01) + fr * ((1 - fc) * d10 + fc * d11)
        g = self.grid
        inside_x = (xy_m[..., 0] > g.origin_x_m + 0.5 * g.resolution_m) & (
            xy_m[..., 0] < g.origin_x_m + (g.cols - 0.5) * g.resolution_m
        )
        inside_y = (xy_m[..., 1] > g.origin_y_m + 0.5 * g.resolution_m) & (
            xy_m[..., 1] < g.origin_y_m + (g.rows - 0.5) * g.resolution_m
        )
        ddx = ((1 - fr) * (d01 - d00) + fr * (d11 - d10)) / g.resolution_m * inside_x
        ddy = ((1 - fc) * (d10 - d00) + fc * (d11 - d01)) / g.resolution_m * inside_y
        return value, np.stack([ddx, ddy], axis=-1)


class ObstacleField(DistanceField):
    """A distance field with obstacle points laid over it: the latest scans' returns that
    the map does not explain (a robot the server does not know, anything standing where
    the map is free), before the map update holds them."""

    def __init__(self, base: DistanceField, points_m: np.ndarray) -> None:
        self.distance_m = base.distance_m
        self.grid = base.grid
        self.points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)

    def value(self, xy_m: np.ndarray) -> np.ndarray:
        return self.value_and_gradient(xy_m)[0]

    def value_and_gradient(self, xy_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xy_m = np.asarray(xy_m, dtype=float)
        value, gradient = super().value_and_gradient(xy_m)
        if len(self.points_m) == 0:
            return value, gradient
        offsets = xy_m[..., None, :] - self.points_m
        gaps = np.linalg.norm(offsets, axis=-1)
        nearest = np.argmin(gaps, axis=-1)
        gap = np.take_along_axis(gaps, nearest[..., None], axis=-1)[..., 0]
        offset = np.take_along_axis(offsets, nearest[..., None, None], axis=-2)[..., 0, :]
        closer = gap < value
        direction = offset / np.maximum(gap, 1e-9)[..., None]
        return np.where(closer, gap, value), np.where(closer[..., None], direction, gradient)
