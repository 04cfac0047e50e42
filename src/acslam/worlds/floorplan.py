"""Floor-plan images (e.g. the IPA room-segmentation maps) as worlds.

Light pixels (grey >= ``free_threshold``) are free, the rest occupied; image rows run
downwards, so they are flipped to make the grid's rows grow with y. Only the largest
connected free region is kept, so the world is one space a robot can explore (the white
outside of a drawn building, or a closed room, would otherwise count as free area).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import ndimage

from acslam.config import FloorplanWorld
from acslam.errors import DataError
from acslam.files import open_image
from acslam.grid import GridSpec
from acslam.worlds.world import World

START_SPACING_M = 0.6
START_CLEARANCE_M = 0.3
START_LATTICE_RINGS = 3
"""Starts are lattice points up to this many spacings from the centre in x and in y."""


def _lattice_offsets(rings: int) -> np.ndarray:
    """(n, 2) integer lattice offsets: the plus (centre, +x, -x, +y, -y) first, so a team
    of up to five starts where it always has, then the rest nearest first (ties
    anticlockwise from +x)."""
    plus = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]
    rest = [
        (i, j)
        for i in range(-rings, rings + 1)
        for j in range(-rings, rings + 1)
        if (i, j) not in plus
    ]
    rest.sort(key=lambda ij: (ij[0] ** 2 + ij[1] ** 2, math.atan2(ij[1], ij[0]) % (2 * math.pi)))
    return np.array(plus + rest, dtype=float)


def read_grey(path: Path) -> np.ndarray:
    """The image as an 8-bit grey array (image row order), or DataError."""
    with open_image(path, "floor-plan image") as image:
        return np.asarray(image.convert("L"))


def floorplan_spec(cfg: FloorplanWorld) -> GridSpec:
    """One cell per pixel, read from the image's header alone."""
    with open_image(Path(cfg.file), "floor-plan image") as image:
        cols, rows = image.size
    return GridSpec(0.0, 0.0, cfg.resolution_m, rows, cols)


def largest_component(free: np.ndarray) -> np.ndarray:
    """Mask of the largest 8-connected region of ``free`` (empty if there is none)."""
    labels, count = ndimage.label(free, structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        return free.copy()
    return labels == np.argmax(np.bincount(labels.ravel())[1:]) + 1


def floorplan_world(cfg: FloorplanWorld) -> World:
    """Load the image; starts are a lattice of poses around the spot of greatest clearance."""
    path = Path(cfg.file)
    free = largest_component(np.flipud(read_grey(path)) >= cfg.free_threshold)
    rows, cols = free.shape
    spec = GridSpec(0.0, 0.0, cfg.resolution_m, rows, cols)
    world = World(name=f"floorplan-{path.stem}", spec=spec, occupied=~free)

    # Every point within (clearance - START_CLEARANCE_M) of the most open cell keeps
    # START_CLEARANCE_M, and so does the straight path between any two of them: the plus
    # of the first five starts.
    clearance = world.clearance_m - 0.5 * cfg.resolution_m
    best = np.unravel_index(np.argmax(clearance), clearance.shape)
    spacing = min(START_SPACING_M, float(clearance[best]) - START_CLEARANCE_M - cfg.resolution_m)
    if spacing <= 0:
        raise DataError(path, f"no free spot with {START_CLEARANCE_M} m clearance for a robot")
    centre = spec.cell_to_world(np.array([best]))[0]
    offsets = _lattice_offsets(START_LATTICE_RINGS)
    xy = offsets * spacing + centre
    # Bigger teams get the lattice beyond the plus: points with START_CLEARANCE_M of their
    # own that a robot can reach from the centre.
    cells = spec.world_to_cell(xy)
    inside = spec.contains(cells)
    cells = np.clip(cells, 0, np.array(spec.shape) - 1)
    reach = world.reachable_free(*centre, START_CLEARANCE_M)
    keep = inside & (clearance[tuple(cells.T)] >= START_CLEARANCE_M) & reach[tuple(cells.T)]
    keep[:5] = True
    starts = np.column_stack([xy[keep], np.zeros(int(keep.sum()))])
    return World(name=world.name, spec=spec, occupied=world.occupied, default_starts=starts)
