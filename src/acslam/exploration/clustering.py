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
    cells: np.ndarray, points_m: np.ndarray, eps_m: float, min_points: int, reach_cells: int
) -> np.ndarray:
    """DBSCAN (Ester et al. 1996) of grid cells, labels as scikit-learn's with its k-d
    tree: cluster 0, 1, ... in the order of their first core point, a border point in the
    first cluster that reaches it, -1 for noise. Points ``i`` and ``j`` are neighbours when
    the squared distance between ``points_m[i]`` and ``points_m[j]`` is at most ``eps_m``
    squared; a core point has at least ``min_points`` neighbours, itself included.

    The cells find their neighbours row by row among the cells sorted by row and column,
    within ``reach_cells`` (more than ``eps_m``, in cells): 2.6x faster than
    scikit-learn's DBSCAN on 4,000 frontier cells, 11x on 100."""
    n = len(cells)
    labels = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return labels
    width = cells[:, 1].max() + reach_cells + 1
    order = np.argsort(cells[:, 0] * width + cells[:, 1])
    rows, cols = cells[order, 0], cells[order, 1]
    first_row, last_row = rows[0], rows[-1]
    row_start = np.searchsorted(rows, np.arange(first_row, last_row + 2))
    eps_sq = eps_m * eps_m
    # Point i's neighbours are neighbours[begin[i]:end[i]].
    begin = np.empty(n, dtype=np.int64)
    end = np.empty(n, dtype=np.int64)
    neighbours = np.empty(16 * n, dtype=np.int64)
    count = 0
    for s in range(n):
        i = order[s]
        begin[i] = count
        for row in range(
            max(rows[s] - reach_cells, first_row), min(rows[s] + reach_cells, last_row) + 1
        ):
            row_end = row_start[row - first_row + 1]
            t = row_start[row - first_row]
            t += np.searchsorted(cols[t:row_end], cols[s] - reach_cells)
            while t < row_end and cols[t] <= cols[s] + reach_cells:
                j = order[t]
                dx = points_m[i, 0] - points_m[j, 0]
                dy = points_m[i, 1] - points_m[j, 1]
                if dx * dx + dy * dy <= eps_sq:
                    if count == len(neighbours):
                        neighbours = np.concatenate((neighbours, np.empty_like(neighbours)))
                    neighbours[count] = j
                    count += 1
                t += 1
        end[i] = count
    core = end - begin >= min_points
    # Depth first from each unlabelled core point: every point it reaches joins it.
    stack = np.empty(count, dtype=np.int64)
    cluster = 0
    for seed in range(n):
        if labels[seed] != -1 or not core[seed]:
            continue
        top = 0
        i = seed
        while True:
            if labels[i] == -1:
                labels[i] = cluster
                if core[i]:
                    for e in range(begin[i], end[i]):
                        if labels[neighbours[e]] == -1:
                            stack[top] = neighbours[e]
                            top += 1
            if top == 0:
                break
            top -= 1
            i = stack[top]
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
    reach_cells = math.floor(params.eps_m / spec.resolution_m) + 1
    labels = dbscan_labels(cells, points_m, params.eps_m, params.min_points, reach_cells)
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
