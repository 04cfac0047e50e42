"""DBSCAN frontier clusters: separation, sizes, snapped targets, information gain."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.cluster import DBSCAN

from acslam.config import CostmapConfig
from acslam.exploration.clustering import UnknownDiscCounter, cluster_frontiers, dbscan_labels
from acslam.exploration.params import DbscanParams
from acslam.grid import GridSpec
from acslam.mapping.costmap import compute_costmap

RES_M = 0.05
SPEC = GridSpec(0.0, 0.0, RES_M, 100, 100)
CONFIG = DbscanParams(eps_m=0.1, min_points=3, min_cluster_size=3)


def test_two_separated_lines_give_two_clusters_of_the_right_sizes() -> None:
    values = np.zeros(SPEC.shape, dtype=np.int8)
    values[:, 60:] = -1
    line_a = np.stack([np.arange(10, 30), np.full(20, 59)], axis=1)  # 20 cells
    line_b = np.stack([np.arange(50, 62), np.full(12, 59)], axis=1)  # 12 cells, 1 m away
    costmap = compute_costmap(values, SPEC, CostmapConfig(), 0.1)
    clusters = cluster_frontiers(np.concatenate([line_a, line_b]), values, SPEC, costmap, CONFIG)
    assert [c.size_cells for c in clusters] == [20, 12]
    for cluster, line in zip(clusters, (line_a, line_b), strict=True):
        assert {tuple(c) for c in cluster.cells.tolist()} == {tuple(c) for c in line.tolist()}
        assert tuple(cluster.target_cell) in {tuple(c) for c in line.tolist()}
        np.testing.assert_allclose(cluster.centroid_m, SPEC.cell_to_world(line).mean(axis=0))


def test_noise_and_small_clusters_are_dropped() -> None:
    values = np.zeros(SPEC.shape, dtype=np.int8)
    costmap = compute_costmap(values, SPEC, CostmapConfig(), 0.1)
    isolated = np.array([[5, 5], [50, 50], [90, 20]])
    assert cluster_frontiers(isolated, values, SPEC, costmap, CONFIG) == []


def test_c_shaped_cluster_snaps_its_target_onto_a_standable_cluster_cell() -> None:
    """A frontier arc around a block: the centroid falls inside the block (a wall)."""
    values = np.zeros(SPEC.shape, dtype=np.int8)
    values[40:60, 40:60] = 100  # the block
    ring = [(r, c) for r in range(36, 64) for c in range(36, 64)]
    arc = np.array([(r, c) for r, c in ring if max(abs(r - 49.5), abs(c - 49.5)) > 13 and c < 62])
    values[arc[:, 0], arc[:, 1]] = 0
    costmap = compute_costmap(values, SPEC, CostmapConfig(), 0.1)
    clusters = cluster_frontiers(arc, values, SPEC, costmap, CONFIG)
    assert len(clusters) == 1
    cluster = clusters[0]
    centroid_cell = SPEC.world_to_cell(cluster.centroid_m)[0]
    assert values[centroid_cell[0], centroid_cell[1]] == 100  # the raw centroid is in the wall
    target = tuple(cluster.target_cell)
    assert target in {tuple(c) for c in arc.tolist()}
    assert not costmap.lethal[target]
    # It is the nearest standable cluster cell to the centroid.
    standable = arc[~costmap.lethal[arc[:, 0], arc[:, 1]]]
    distance = np.linalg.norm(SPEC.cell_to_world(standable) - cluster.centroid_m, axis=1)
    assert np.isclose(
        np.linalg.norm(cluster.target_m - cluster.centroid_m), distance.min(), atol=1e-12
    )


def test_information_gain_counts_unknown_cells_in_the_sensor_disc() -> None:
    rng = np.random.default_rng(3)
    values = rng.choice(np.array([-1, 0, 100], dtype=np.int8), SPEC.shape)
    radius_m = 0.8
    counter = UnknownDiscCounter(values, RES_M, radius_m)
    rows, cols = np.indices(SPEC.shape)
    for cell in [(0, 0), (50, 50), (99, 3), (10, 95)]:
        within = (rows - cell[0]) ** 2 + (cols - cell[1]) ** 2 <= (radius_m / RES_M) ** 2
        assert counter.count(np.array(cell)) == int((within & (values == -1)).sum())


def frontier_walks(rng: np.random.Generator, cells: int, size: int) -> np.ndarray:
    """Distinct cells of random 8-connected walks, in random order: frontier-like."""
    found: set[tuple[int, int]] = set()
    while len(found) < cells:
        r, c = rng.integers(0, size, 2)
        for _ in range(rng.integers(1, 60)):
            found.add((int(r), int(c)))
            r, c = np.clip(np.array([r, c]) + rng.integers(-1, 2, 2), 0, size - 1)
            if len(found) == cells:
                break
    return rng.permutation(np.array(sorted(found), dtype=np.int64))


@pytest.mark.parametrize("seed", range(24))
def test_dbscan_labels_equal_scikit_learns(seed: int) -> None:
    """The same labels as scikit-learn's DBSCAN with its k-d tree, on walks of 6 to 3,000
    cells, with eps a whole number of cells (neighbours exactly eps apart) or not."""
    rng = np.random.default_rng(seed)
    cells = frontier_walks(rng, int(rng.choice([6, 11, 40, 300, 3000])), 400)
    spec = GridSpec(*rng.uniform(-50, 50, 2).round(2), RES_M, 400, 400)
    points_m = spec.cell_to_world(cells)
    eps_m = float(rng.choice([0.1, 0.25, 0.3, 0.33]))
    min_points = int(rng.choice([3, 5, 8]))
    reference = DBSCAN(eps=eps_m, min_samples=min_points, algorithm="kd_tree").fit_predict(points_m)
    labels = dbscan_labels(cells, points_m, eps_m, min_points, RES_M)
    np.testing.assert_array_equal(labels, reference)


def test_a_cluster_needs_enough_cells_a_robot_may_stand_on() -> None:
    """A frontier line running into a wall: the cells in the wall's lethal band count
    toward the cluster's size, not toward the cells it needs. With one standable cell
    fewer than ``min_cluster_size`` the line is dropped, with exactly that many it is a
    cluster of all its cells."""
    values = np.zeros(SPEC.shape, dtype=np.int8)
    values[:, 50:] = 100  # a wall from column 50 on
    costmap = compute_costmap(values, SPEC, CostmapConfig(), 0.1)
    lethal_band = int(costmap.lethal[30, :50].sum())
    assert lethal_band >= 2  # the robot radius is two cells
    needed = CONFIG.min_cluster_size
    for standable, kept in ((needed - 1, False), (needed, True)):
        length = lethal_band + standable
        line = np.stack([np.full(length, 30), np.arange(50 - length, 50)], axis=1)
        clusters = cluster_frontiers(line, values, SPEC, costmap, CONFIG)
        assert len(clusters) == int(kept)
        if kept:
            assert clusters[0].size_cells == length
            assert not costmap.lethal[tuple(clusters[0].target_cell)]
