"""The ground-truth world: a boolean occupancy grid plus where robots may start."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numba
import numpy as np
from scipy import ndimage

from acslam.grid import GridSpec


@numba.njit(cache=True)
def _clearance(
    occupied: np.ndarray, x0: float, y0: float, res: float, x: float, y: float, max_m: float
) -> float:
    """Distance from a point to the nearest occupied (or off-grid) cell square, capped."""
    rows, cols = occupied.shape
    cx = (x - x0) / res
    cy = (y - y0) / res
    reach = int(max_m / res) + 2
    col0 = math.floor(cx)
    row0 = math.floor(cy)
    best = max_m / res
    for row in range(row0 - reach, row0 + reach + 1):
        dy = max(row - cy, 0.0, cy - (row + 1))
        if dy >= best:
            continue
        for col in range(col0 - reach, col0 + reach + 1):
            inside = 0 <= row < rows and 0 <= col < cols
            if inside and not occupied[row, col]:
                continue
            dx = max(col - cx, 0.0, cx - (col + 1))
            distance = math.sqrt(dx * dx + dy * dy)
            if distance < best:
                best = distance
    return best * res


@dataclass(frozen=True, eq=False)
class World:
    """Ground truth for simulation and evaluation; the server never sees it.

    ``occupied[row, col]`` is True for obstacle cells (see :mod:`acslam.grid` for the
    axes). ``default_starts`` is an (K, 3) array of ``[x, y, theta]`` start poses the
    generator suggests, used when a scenario gives none.

    ``discs`` (D, 3) ``[x, y, radius]`` are round obstacles (plants, trunks). They are
    stamped into ``occupied``, which the truth map, collisions and planning use, but the
    LiDAR sees them as circles: ``occupied_without_discs`` is the grid it casts against,
    plus the discs themselves. A disc stamped into 5 cm cells is a staircase whose step
    faces each show to one side only, so two scans from different places see different
    faces: along a vineyard row that biased scan matching by 0.6-1 % of the distance,
    twice what true circles do, an artefact real plants do not have.
    """

    name: str
    spec: GridSpec
    occupied: np.ndarray
    default_starts: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    discs: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    occupied_without_discs: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.occupied.shape != self.spec.shape or self.occupied.dtype != bool:
            raise ValueError(
                f"world {self.name!r}: occupied must be a bool array of shape {self.spec.shape}"
            )
        if self.discs.ndim != 2 or self.discs.shape[1] != 3:
            raise ValueError(f"world {self.name!r}: discs must be (D, 3) [x, y, radius]")
        rest = self.occupied_without_discs
        if rest is not None and (rest.shape != self.spec.shape or rest.dtype != bool):
            raise ValueError(
                f"world {self.name!r}: occupied_without_discs must be a bool array of shape "
                f"{self.spec.shape}"
            )

    @property
    def lidar_grid(self) -> np.ndarray:
        """The cells the LiDAR casts against (``discs`` are added as circles)."""
        return self.occupied if self.occupied_without_discs is None else self.occupied_without_discs

    @property
    def free(self) -> np.ndarray:
        return ~self.occupied

    @cached_property
    def clearance_m(self) -> np.ndarray:
        """Distance in metres from each cell centre to the nearest occupied cell centre.

        Cells outside the grid count as occupied, so the border is a wall.
        """
        padded = np.pad(self.free, 1, constant_values=False)
        dist = ndimage.distance_transform_edt(padded)[1:-1, 1:-1]
        return dist * self.spec.resolution_m

    def clearance_at(self, x: float, y: float, max_m: float = 1.0) -> float:
        """Exact distance in metres from (x, y) to the nearest obstacle cell, capped at max_m.

        Obstacle cells are squares and cells beyond the grid count as obstacles, so a
        disc of radius r at (x, y) touches nothing exactly when the result is >= r.
        """
        spec = self.spec
        return _clearance(
            self.occupied, spec.origin_x_m, spec.origin_y_m, spec.resolution_m, x, y, max_m
        )

    def free_area_m2(self) -> float:
        return float(self.free.sum()) * self.spec.resolution_m**2

    def reachable_free(self, x: float, y: float, robot_radius_m: float = 0.0) -> np.ndarray:
        """Mask of free cells connected (8-neighbourhood) to (x, y).

        With ``robot_radius_m`` > 0, connectivity is through cells where a disc of that
        radius fits, and the mask is then grown back by the radius: the area such a robot
        can sweep.
        """
        passable = self.free
        if robot_radius_m > 0:
            passable = self.clearance_m - 0.5 * self.spec.resolution_m >= robot_radius_m
        labels, _ = ndimage.label(passable, structure=np.ones((3, 3), dtype=bool))
        row, col = self.spec.world_to_cell(np.array([[x, y]]))[0]
        if not self.spec.contains(np.array([[row, col]]))[0] or labels[row, col] == 0:
            return np.zeros(self.spec.shape, dtype=bool)
        mask = labels == labels[row, col]
        if robot_radius_m > 0:
            dist_to_mask = ndimage.distance_transform_edt(~mask) * self.spec.resolution_m
            mask = (dist_to_mask <= robot_radius_m) & self.free
        return mask
