"""Frontier clustering with DBSCAN (thesis §4.5) and per-cluster navigation targets.

A cluster's centroid can fall off the cluster (a C-shaped frontier around a pillar) or in
a wall, where no robot can go: the target is therefore the cluster's own frontier cell
nearest to the centroid among those the robot may occupy (not lethal on the costmap). A
cluster with no such cell is dropped: no robot could stand on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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


def cluster_frontiers(
    frontier_cells: np.ndarray,
    values: np.ndarray,
    spec: GridSpec,
    costmap: Costmap,
    params: DbscanParams,
) -> list[FrontierCluster]:
    """DBSCAN of the frontier cell centres (metres) into targets, largest cluster first.

    ``values``: the OccupancyGrid values the frontiers came from (for information gain).
    Noise points and clusters smaller than ``min_cluster_size`` cells are dropped.
    """
    cells = np.asarray(frontier_cells, dtype=np.int64).reshape(-1, 2)
    if len(cells) < params.min_points:
        return []
    points_m = spec.cell_to_world(cells)
    # scikit-learn takes 0.6 s to import: only runs that cluster pay it, not the CLI.
    from sklearn.cluster import DBSCAN

    labels = DBSCAN(eps=params.eps_m, min_samples=params.min_points).fit_predict(points_m)
    counter = UnknownDiscCounter(values, spec.resolution_m, params.information_gain_radius_m)
    clusters = []
    for label in np.unique(labels[labels >= 0]):
        members = labels == label
        if members.sum() < params.min_cluster_size:
            continue
        member_cells = cells[members]
        centroid_m = points_m[members].mean(axis=0)
        standable = ~costmap.lethal[member_cells[:, 0], member_cells[:, 1]]
        if not standable.any():
            continue
        candidates = member_cells[standable]
        distance_sq = ((points_m[members][standable] - centroid_m) ** 2).sum(axis=1)
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
