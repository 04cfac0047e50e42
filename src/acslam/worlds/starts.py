"""Seeded random start poses, spread over the world: ``robots.starts: random``.

Real teams are set down wherever there is room, in different rooms and facing different
ways. A draw places each robot in the largest connected space a robot fits through (so
every robot can reach every other's start), at least ``START_CLEARANCE_RADII`` robot radii
from the nearest wall, at least ``min_separation_m`` from every other start, and out of
sight of every other start: the straight line between two starts crosses a wall. Headings
are uniform. The draw is rejection sampling: each robot tries up to
``CANDIDATES_PER_ROBOT`` cells, and a team that cannot be completed is drawn again, up to
``ATTEMPTS`` times, before the world is declared too small for the request.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from acslam.sim.lidar import grid_ray_m
from acslam.worlds.world import World

START_CLEARANCE_RADII = 2.0
"""A start leaves a robot's width of room around the robot, so it can turn in place."""
CANDIDATES_PER_ROBOT = 2000
ATTEMPTS = 50


def line_of_sight(world: World, a_xy: np.ndarray, b_xy: np.ndarray) -> bool:
    """Whether a ray from ``a_xy`` reaches ``b_xy`` without entering an occupied cell: the
    exact grid traversal the simulated LiDAR and camera see by."""
    delta = np.asarray(b_xy, dtype=float) - np.asarray(a_xy, dtype=float)
    distance_m = float(np.hypot(*delta))
    if distance_m == 0.0:
        return True
    spec = world.spec
    reach_m = grid_ray_m(
        world.occupied,
        spec.origin_x_m,
        spec.origin_y_m,
        spec.resolution_m,
        float(a_xy[0]),
        float(a_xy[1]),
        float(delta[0]) / distance_m,
        float(delta[1]) / distance_m,
        distance_m,
    )
    return reach_m >= distance_m


def _candidate_cells(world: World, radius_m: float) -> np.ndarray:
    """(N, 2) cells of the largest connected space with the start clearance."""
    spec = world.spec
    # A cell's centre is within half a cell diagonal of any point of the cell square
    # nearest to it, so this bounds the exact clearance of the centre from below.
    half_diagonal_m = 0.5 * math.sqrt(2.0) * spec.resolution_m
    roomy = world.clearance_m - half_diagonal_m >= START_CLEARANCE_RADII * radius_m
    labels, count = ndimage.label(roomy, structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        return np.zeros((0, 2), dtype=np.int64)
    sizes = np.bincount(labels.ravel())[1:]
    return np.argwhere(labels == 1 + int(np.argmax(sizes)))


def draw_random_starts(
    world: World,
    count: int,
    radius_m: float,
    min_separation_m: float,
    generator: np.random.Generator,
) -> np.ndarray | None:
    """(count, 3) ``[x, y, theta]`` start poses as the module docstring says, or None when
    ``ATTEMPTS`` draws found no such team."""
    cells = _candidate_cells(world, radius_m)
    if len(cells) == 0:
        return None
    spec = world.spec
    for _ in range(ATTEMPTS):
        chosen: list[np.ndarray] = []
        for _robot in range(count):
            picks = cells[generator.integers(0, len(cells), size=CANDIDATES_PER_ROBOT)]
            centres = spec.cell_to_world(picks)
            for xy in centres:
                if all(
                    np.hypot(*(xy - other)) >= min_separation_m
                    and not line_of_sight(world, xy, other)
                    for other in chosen
                ):
                    chosen.append(xy)
                    break
            else:
                break
        if len(chosen) == count:
            headings = generator.uniform(-math.pi, math.pi, size=count)
            return np.column_stack([np.array(chosen), headings])
    return None
