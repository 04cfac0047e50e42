"""Camera landmarks: points on structure the robots can see and re-identify.

Landmarks stand where features are in a real scene, on or near walls and objects: they
are drawn uniformly among free cells within ``max_obstacle_distance_m`` of an obstacle,
with a count proportional to the (reachable) free area.
"""

from __future__ import annotations

import numpy as np

from acslam.config import LandmarkConfig
from acslam.worlds.world import World


def place_landmarks(
    world: World,
    cfg: LandmarkConfig,
    rng: np.random.Generator,
    reachable: np.ndarray | None = None,
) -> np.ndarray:
    """(L, 3) landmark positions ``[x, y, z]``.

    ``L = round(density_per_m2 * area)`` with the area of ``reachable`` (a mask of the
    grid's shape) if given, else of all free cells; no landmarks if no cell qualifies.
    """
    region = world.free if reachable is None else (reachable & world.free)
    spec = world.spec
    count = round(cfg.density_per_m2 * float(region.sum()) * spec.resolution_m**2)
    rows, cols = np.nonzero(region & (world.clearance_m <= cfg.max_obstacle_distance_m))
    if count == 0 or len(rows) == 0:
        return np.zeros((0, 3))
    pick = rng.integers(0, len(rows), size=count)
    inside = rng.random((count, 2))
    x = spec.origin_x_m + (cols[pick] + inside[:, 0]) * spec.resolution_m
    y = spec.origin_y_m + (rows[pick] + inside[:, 1]) * spec.resolution_m
    z = rng.uniform(cfg.z_min_m, cfg.z_max_m, size=count)
    return np.column_stack([x, y, z])
