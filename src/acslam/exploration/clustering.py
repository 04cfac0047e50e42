"""Frontier clustering with DBSCAN (thesis §4.5) and per-cluster navigation targets.

A cluster's centroid can fall off the cluster (a C-shaped frontier around a pillar) or in
a wall, where no robot can go: the target is therefore the cluster's own frontier cell
nearest to the centroid among those the robot may occupy (not lethal on the costmap).

A cluster needs ``min_cluster_size`` such cells, not only that many cells. Beside a wall
the floor cells the LiDAR only grazes stay unknown, and the free cells next to them are
frontier cells in the wall's lethal band: on dungeon-40 (random starts, seed 0, unknown
starts) a five-cell fragment with one standable cell came and went with each map update
between 245 and 315 s, now five cells, now four, and a robot 5-8 m from it
turned back and forth between it and a cluster 20 m away for those 70 s. No robot can
stand where such a fragment is, so no robot can see behind it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from acslam.exploration.params import DbscanParams
from acslam.grid import UNKNOWN, GridSpec
from acslam.mapping.costmap import Costmap


@dataclass(frozen=True)
class FrontierCluster:
    """One exploration frontier: its cells, centroid, target and utility.

    ``cells``: (n, 2) ``[row, col]``; ``centroid_m``: mean of the cell centres ``[x, y]``;
    ``target_cell``/``target_m``: the snapped goal; ``size_cells``: n;
    ``information_gain_cells``: unknown cells within the configured radius of the target.
    """

    cells: np.ndarray
    centroid_m: np.ndarray
    target_cell: np.ndarray
    target_m: np.ndarray
    size_cells: int
    information_gain_cells: int


class UnknownDiscCounter:
    """Counts unknown cells in discs in O(radius) per disc.

    Per-row prefix sums of the unknown mask turn each row of a disc into one difference;
    one ``cumsum`` over the grid serves all clusters.
    """

    def __init__(self, values: np.ndarray, resolution_m: float, radius_m: float) -> None:
        unknown = (np.asarray(values) == UNKNOWN).astype(np.int32)
        self._prefix = np.zeros((unknown.shape[0], unknown.shape[1] + 1), dtype=np.int32)
        np.cumsum(unknown, axis=1, out=self._prefix[:, 1:])
        radius_cells = radius_m / resolution_m
        span = math.floor(radius_cells + 1e-9)
        self._row_offsets = np.arange(-span, span + 1)
        # Cells whose centre lies within the radius of the centre cell's centre.
        self._half_widths = np.floor(
            np.sqrt(np.maximum(radius_cells**2 - self._row_offsets**2, 0.0)) + 1e-9
        ).astype(np.int64)

    def count(self, cell: np.ndarray) -> int:
        """Unknown cells in the disc around ``cell`` (``[row, col]``), clipped to the grid."""
        rows, width = self._prefix.shape
        r = int(cell[0]) + self._row_offsets
        inside = (r >= 0) & (r < rows)
        r = r[inside]
        half = self._half_widths[inside]
        lo = np.clip(int(cell[1]) - half, 0, width - 1)
        hi = np.clip(int(cell[1]) + half + 1, 0, width - 1)
        return int((self._prefix[r, hi] - self._prefix[r, lo]).sum())


@numba.njit(cache=True, nogil=True)
def dbscan_labels(
    cells: np.ndarray, points_m: np.ndarray, eps_m: float, min_points: int, resolution_m: float
) -> np.ndarray:
    """DBSCAN (Ester et al. 1996) of distinct grid cells, labels as scikit-learn's with its
    k-d tree: cluster 0, 1, ... in the order of their first core point, a border point in
    the first cluster that reaches it, -1 for noise. ``points_m`` are the cells' centres on
    a grid of ``resolution_m``. Points ``i`` and ``j`` are neighbours when the squared
    distance between ``points_m[i]`` and ``points_m[j]`` is at most ``eps_m`` squared; a
    core point has at least ``min_points`` neighbours, itself included.

    The cells are bucketed in square tiles of ``reach`` cells (more than ``eps_m``), so a
    cell's neighbours lie in its own tile and the eight around it, and nothing stores the
    neighbours. The tiles' table grows with the cells' bounding box over ``reach``
    squared (0.3 M tiles for 4,000 x 4,000 cells). Against searching the cells sorted by
    row and column (the same labels): 0.3 of the time on 1,600-11,600 frontier cells of
    office_a, 0.9 on 4,000 cells spread over 4,000 x 4,000. An image of the cells' box
    indexed at fixed offsets was as fast on office_a but 7x slower at that size."""
    n = len(cells)
    labels = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return labels
    reach = int(eps_m / resolution_m) + 1
    tile_row = (cells[:, 0] - cells[:, 0].min()) // reach
    tile_col = (cells[:, 1] - cells[:, 1].min()) // reach
    tile_rows, tile_cols = tile_row.max() + 1, tile_col.max() + 1
    tile = tile_row * tile_cols + tile_col
    # Tile t holds the cells members[starts[t]:starts[t + 1]].
    starts = np.zeros(tile_rows * tile_cols + 1, dtype=np.int64)
    for i in range(n):
        starts[tile[i] + 1] += 1
    starts = np.cumsum(starts)
    filled = starts[:-1].copy()
    members = np.empty(n, dtype=np.int64)
    for i in range(n):
        members[filled[tile[i]]] = i
        filled[tile[i]] += 1
    eps_sq = eps_m * eps_m
    core = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        found = 0
        for tr in range(max(tile_row[i] - 1, 0), min(tile_row[i] + 2, tile_rows)):
            for tc in range(max(tile_col[i] - 1, 0), min(tile_col[i] + 2, tile_cols)):
                t = tr * tile_cols + tc
                for e in range(starts[t], starts[t + 1]):
                    j = members[e]
                    dx = points_m[i, 0] - points_m[j, 0]
                    dy = points_m[i, 1] - points_m[j, 1]
                    found += dx * dx + dy * dy <= eps_sq
        core[i] = found >= min_points
    # Grow each cluster from its first unlabelled core point: every point a core point of
    # the cluster reaches joins it (labelled when first reached, so the stack holds each
    # point at most once).
    stack = np.empty(n, dtype=np.int64)
    cluster = 0
    for seed in range(n):
        if labels[seed] != -1 or not core[seed]:
            continue
        labels[seed] = cluster
        stack[0] = seed
        top = 1
        while top > 0:
            top -= 1
            i = stack[top]
            if not core[i]:
                continue
            for tr in range(max(tile_row[i] - 1, 0), min(tile_row[i] + 2, tile_rows)):
                for tc in range(max(tile_col[i] - 1, 0), min(tile_col[i] + 2, tile_cols)):
                    t = tr * tile_cols + tc
                    for e in range(starts[t], starts[t + 1]):
                        j = members[e]
                        if labels[j] != -1:
                            continue
                        dx = points_m[i, 0] - points_m[j, 0]
                        dy = points_m[i, 1] - points_m[j, 1]
                        if dx * dx + dy * dy <= eps_sq:
                            labels[j] = cluster
                            stack[top] = j
                            top += 1
        cluster += 1
    return labels


def cluster_frontiers(
    frontier_cells: np.ndarray,
    values: np.ndarray,
    spec: GridSpec,
    costmap: Costmap,
    params: DbscanParams,
) -> list[FrontierCluster]:
    """DBSCAN of the frontier cell centres (metres) into targets, largest cluster first.

    ``values``: the OccupancyGrid values the frontiers came from (for information gain).
    Noise points and clusters with fewer than ``min_cluster_size`` cells a robot may
    stand on (not lethal on ``costmap``) are dropped; the size is all member cells.
    """
    cells = np.asarray(frontier_cells, dtype=np.int64).reshape(-1, 2)
    if len(cells) < params.min_points:
        return []
    points_m = spec.cell_to_world(cells)
    labels = dbscan_labels(cells, points_m, params.eps_m, params.min_points, spec.resolution_m)
    counter = UnknownDiscCounter(values, spec.resolution_m, params.information_gain_radius_m)
    clusters = []
    for label in np.unique(labels[labels >= 0]):
        members = labels == label
        member_cells = cells[members]
        standable = ~costmap.lethal[member_cells[:, 0], member_cells[:, 1]]
        if standable.sum() < params.min_cluster_size:
            continue
        member_points_m = points_m[members]
        centroid_m = member_points_m.mean(axis=0)
        candidates = member_cells[standable]
        distance_sq = ((member_points_m[standable] - centroid_m) ** 2).sum(axis=1)
        target = candidates[int(np.argmin(distance_sq))]
        clusters.append(
            FrontierCluster(
                cells=member_cells,
                centroid_m=centroid_m,
                target_cell=target,
                target_m=spec.cell_to_world(target)[0],
                size_cells=int(members.sum()),
                information_gain_cells=counter.count(target),
            )
        )
    clusters.sort(key=lambda cluster: -cluster.size_cells)
    return clusters


class DbscanClusterer:
    """:func:`cluster_frontiers` with the scenario's parameters."""

    def __init__(self, params: DbscanParams) -> None:
        self.params = params

    @property
    def linkage_m(self) -> float:
        return self.params.eps_m

    def cluster(
        self, frontier_cells: np.ndarray, values: np.ndarray, spec: GridSpec, costmap: Costmap
    ) -> list[FrontierCluster]:
        return cluster_frontiers(frontier_cells, values, spec, costmap, self.params)
