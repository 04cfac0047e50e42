"""Exact nearest neighbours within a distance bound among a scan's 2D points.

ICP asks this of every query point at every iteration: a few hundred to a thousand points
against as many, with a bound of at most a metre (the correspondence gate). scipy's
cKDTree answers it, but at about 0.15 ms a call for 330 points against 330 (0.46 us a
point, office_a, LDS-02 scans), most of it the tree walk of each point alone. Here the
points are bucketed once in square cells (CSR by cell) and each query looks through rings
of cells around its own, nearest ring first, until no point of a further ring can be
nearer than the best found or within the bound. The answer is cKDTree's: the same
squared distance ``dx * dx + dy * dy``, accepted when below the bound squared, and its
square root; only exact ties may pick another point. On 3,913 of office_a's ICP calls
(1.3 million query points) every index and distance was cKDTree's;
``tests/mapping/test_nearest_points.py`` compares both with brute force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

CELLS_PER_POINT = 1.0
"""The grid has about this many cells per point over the points' bounding box (cells no
smaller than :data:`MIN_CELL_M`): a long-range scan of a large hall gets large cells
instead of a grid of millions. Speed barely depends on it: 0.027-0.030 ms a call for
0.5-8 cells per point and 0.05-0.2 m floors, on office_a's matches."""

MIN_CELL_M = 0.05
"""The smallest cell: a few points bunched in one place would otherwise get cells of
micrometres."""


@dataclass(frozen=True, eq=False)
class PointGrid:
    """Points bucketed in cells of ``cell_m``: cell (row, col) holds
    ``order[starts[row * cols + col] : starts[row * cols + col + 1]]``, whose coordinates
    are the same rows of ``sorted_points_m``."""

    origin_m: np.ndarray
    cell_m: float
    rows: int
    cols: int
    starts: np.ndarray
    order: np.ndarray
    sorted_points_m: np.ndarray

    def nearest_within(
        self, queries_m: np.ndarray, bound_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per query point, the distance to the nearest point and its index, if nearer
        than ``bound_m``; else ``inf`` and -1."""
        return _nearest_within(
            np.ascontiguousarray(queries_m, dtype=float), float(bound_m), self.origin_m,
            self.cell_m, self.rows, self.cols, self.starts, self.order, self.sorted_points_m,
        )  # fmt: skip


def point_grid(points_m: np.ndarray) -> PointGrid:
    """Bucket (N, 2) points for :meth:`PointGrid.nearest_within`."""
    points = np.ascontiguousarray(points_m, dtype=float).reshape(-1, 2)
    if len(points) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return PointGrid(np.zeros(2), 1.0, 0, 0, np.zeros(1, dtype=np.int64), empty, points)
    low = points.min(axis=0)
    extent = points.max(axis=0) - low
    area = float(max(extent[0], MIN_CELL_M) * max(extent[1], MIN_CELL_M))
    cell_m = max(MIN_CELL_M, math.sqrt(area / (CELLS_PER_POINT * len(points))))
    # Cells as the queries find them: floor of the offset over the cell size.
    at = np.floor((points - low) / cell_m).astype(np.int64)
    cols, rows = int(at[:, 0].max()) + 1, int(at[:, 1].max()) + 1
    cells = at[:, 1] * cols + at[:, 0]
    order = np.argsort(cells, kind="stable")
    starts = np.searchsorted(cells[order], np.arange(rows * cols + 1))
    return PointGrid(low, cell_m, rows, cols, starts, order, np.ascontiguousarray(points[order]))


@numba.njit(cache=True)
def _nearest_within(
    queries: np.ndarray,
    bound_m: float,
    origin: np.ndarray,
    cell_m: float,
    rows: int,
    cols: int,
    starts: np.ndarray,
    order: np.ndarray,
    points: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`PointGrid.nearest_within` on the grid's arrays."""
    count = queries.shape[0]
    distances = np.full(count, np.inf)
    matches = np.full(count, -1, dtype=np.int64)
    if rows == 0:
        return distances, matches
    bound_sq = bound_m * bound_m
    max_ring = math.ceil(bound_m / cell_m) + 1
    for i in range(count):
        qx = queries[i, 0] - origin[0]
        qy = queries[i, 1] - origin[1]
        outside_x = max(0.0, -qx, qx - cols * cell_m)
        outside_y = max(0.0, -qy, qy - rows * cell_m)
        if outside_x * outside_x + outside_y * outside_y >= bound_sq:
            continue  # the whole grid is beyond the bound
        col = math.floor(qx / cell_m)
        row = math.floor(qy / cell_m)
        best_sq = bound_sq
        best = -1
        for ring in range(max_ring + 1):
            if ring > 0:
                # No point outside the (2 ring - 1)^2 cells already searched is nearer
                # than the edge of that block.
                edge_m = min(
                    qx - (col - ring + 1) * cell_m,
                    (col + ring) * cell_m - qx,
                    qy - (row - ring + 1) * cell_m,
                    (row + ring) * cell_m - qy,
                )
                if edge_m > 0.0 and edge_m * edge_m >= best_sq:
                    break
            for r in range(max(row - ring, 0), min(row + ring, rows - 1) + 1):
                edge_row = r == row - ring or r == row + ring
                step = 1 if edge_row else 2 * ring
                c = col - ring
                while c <= col + ring:
                    if 0 <= c < cols:
                        cell = r * cols + c
                        for k in range(starts[cell], starts[cell + 1]):
                            dx = points[k, 0] - queries[i, 0]
                            dy = points[k, 1] - queries[i, 1]
                            d_sq = dx * dx + dy * dy
                            if d_sq < best_sq:
                                best_sq = d_sq
                                best = k
                    c += step
        if best >= 0:
            distances[i] = math.sqrt(best_sq)
            matches[i] = order[best]
    return distances, matches
