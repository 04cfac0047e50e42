"""Grid geometry shared by worlds, maps and planners.

Cell ``(row, col)`` covers ``x in [x0 + col*res, x0 + (col+1)*res)`` and
``y in [y0 + row*res, y0 + (row+1)*res)``: rows grow with y (y-up, as in ROS maps once
the image rows are flipped), so ``array[row, col]`` indexing matches ``(y, x)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

UNKNOWN, FREE, OCCUPIED = -1, 0, 100
"""ROS ``OccupancyGrid`` cell values: every occupancy array of acslam uses these."""

NEIGHBOUR_ROWS = np.array([-1, -1, -1, 0, 0, 1, 1, 1], dtype=np.int64)
NEIGHBOUR_COLS = np.array([-1, 0, 1, -1, 1, -1, 0, 1], dtype=np.int64)
"""Row and column offsets of a cell's 8 neighbours, diagonals included."""


@numba.njit(cache=True, inline="always")
def neighbour_flat(row: int, col: int, k: int, rows: int, cols: int) -> int:
    """Flat index of the ``k``-th 8-neighbour of cell (row, col); -1 outside the grid.

    Flat kernels (EWFD) walk neighbourhoods through this one helper, in the order of
    ``NEIGHBOUR_ROWS``/``NEIGHBOUR_COLS``; the caller splits its flat cell once per walk.
    """
    r = row + NEIGHBOUR_ROWS[k]
    c = col + NEIGHBOUR_COLS[k]
    if 0 <= r < rows and 0 <= c < cols:
        return r * cols + c
    return -1


@dataclass(frozen=True)
class GridSpec:
    """Placement of a 2D grid in the world frame (units: metres)."""

    origin_x_m: float
    origin_y_m: float
    resolution_m: float
    rows: int
    cols: int

    @property
    def shape(self) -> tuple[int, int]:
        return (self.rows, self.cols)

    @property
    def width_m(self) -> float:
        return self.cols * self.resolution_m

    @property
    def height_m(self) -> float:
        return self.rows * self.resolution_m

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(left, right, bottom, top) in metres, as matplotlib's ``imshow(extent=...)``."""
        return (
            self.origin_x_m,
            self.origin_x_m + self.width_m,
            self.origin_y_m,
            self.origin_y_m + self.height_m,
        )

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world points -> (N, 2) integer ``[row, col]`` (may lie outside the grid)."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        col = np.floor((xy[:, 0] - self.origin_x_m) / self.resolution_m).astype(np.int64)
        row = np.floor((xy[:, 1] - self.origin_y_m) / self.resolution_m).astype(np.int64)
        return np.stack([row, col], axis=1)

    def cell_to_world(self, cells: np.ndarray) -> np.ndarray:
        """(N, 2) ``[row, col]`` -> (N, 2) world ``[x, y]`` of the cell centres."""
        cells = np.atleast_2d(np.asarray(cells))
        x = self.origin_x_m + (cells[:, 1] + 0.5) * self.resolution_m
        y = self.origin_y_m + (cells[:, 0] + 0.5) * self.resolution_m
        return np.stack([x, y], axis=1)

    def contains(self, cells: np.ndarray) -> np.ndarray:
        """Boolean mask of the ``[row, col]`` cells that lie inside the grid."""
        cells = np.atleast_2d(cells)
        return (
            (cells[:, 0] >= 0)
            & (cells[:, 0] < self.rows)
            & (cells[:, 1] >= 0)
            & (cells[:, 1] < self.cols)
        )


@dataclass(frozen=True)
class Window:
    """A rectangle of a larger grid: its rows ``[row0, row0 + spec.rows)``, its columns
    ``[col0, col0 + spec.cols)``, and ``spec`` placing it in the world."""

    row0: int
    col0: int
    spec: GridSpec

    def crop(self, array: np.ndarray) -> np.ndarray:
        return array[self.row0 : self.row0 + self.spec.rows, self.col0 : self.col0 + self.spec.cols]

    def to_local(self, cells: np.ndarray) -> np.ndarray:
        return np.asarray(cells) - np.array([self.row0, self.col0])


def window_around(spec: GridSpec, center_xy_m: np.ndarray, half_size_m: float) -> Window:
    """The cells within ``half_size_m`` (per axis) of a point, clipped to the grid (at
    least one cell, the nearest)."""
    res = spec.resolution_m
    c0, r0 = np.floor((np.asarray(center_xy_m) - half_size_m - spec.extent_m[::2]) / res)
    c1, r1 = np.floor((np.asarray(center_xy_m) + half_size_m - spec.extent_m[::2]) / res) + 1
    r0, r1 = int(np.clip(r0, 0, spec.rows - 1)), int(np.clip(r1, 1, spec.rows))
    c0, c1 = int(np.clip(c0, 0, spec.cols - 1)), int(np.clip(c1, 1, spec.cols))
    r1, c1 = max(r1, r0 + 1), max(c1, c0 + 1)
    local = GridSpec(spec.origin_x_m + c0 * res, spec.origin_y_m + r0 * res, res, r1 - r0, c1 - c0)
    return Window(r0, c0, local)


@numba.njit(cache=True, nogil=True)
def bresenham_start(r0: int, c0: int, r1: int, c1: int) -> tuple[int, int, int, int, int, int]:
    """Bresenham's line from ``(r0, c0)`` to ``(r1, c1)``: its cell count minus one and
    the state :func:`bresenham_step` advances, ``(error, row span, column span, row step,
    column step)``. Stepping a line cell by cell, instead of building
    :func:`bresenham`'s array, spares a hot loop an allocation per line."""
    drow, dcol = abs(r1 - r0), abs(c1 - c0)
    return max(drow, dcol), dcol - drow, drow, dcol, 1 if r1 >= r0 else -1, 1 if c1 >= c0 else -1


@numba.njit(cache=True, nogil=True)
def bresenham_step(
    r: int, c: int, err: int, drow: int, dcol: int, step_r: int, step_c: int
) -> tuple[int, int, int]:
    """The line's next cell after ``(r, c)`` and the new error (see :func:`bresenham_start`)."""
    twice = 2 * err
    if twice >= -drow:
        err -= drow
        c += step_c
    if twice <= dcol:
        err += dcol
        r += step_r
    return r, c, err


@numba.njit(cache=True)
def bresenham(r0: int, c0: int, r1: int, c1: int) -> np.ndarray:
    """Cells of the Bresenham line from ``(r0, c0)`` to ``(r1, c1)``, both included.

    Returns an (N, 2) int64 array of ``[row, col]`` in order from the start cell.
    """
    steps, err, drow, dcol, step_r, step_c = bresenham_start(r0, c0, r1, c1)
    out = np.empty((steps + 1, 2), dtype=np.int64)
    r, c = r0, c0
    for i in range(steps + 1):
        out[i, 0] = r
        out[i, 1] = c
        r, c, err = bresenham_step(r, c, err, drow, dcol, step_r, step_c)
    return out
