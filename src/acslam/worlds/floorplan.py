"""Floor-plan images (e.g. the IPA room-segmentation maps) as worlds.

Light pixels (grey >= ``free_threshold``) are free, the rest occupied; image rows run
downwards, so they are flipped to make the grid's rows grow with y. Only the largest
connected free region is kept, so the world is one space a robot can explore (the white
outside of a drawn building, or a closed room, would otherwise count as free area).
"""

from __future__ import annotations

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
    """Load the image; starts are a plus of poses at the spot of greatest clearance."""
    path = Path(cfg.file)
    free = largest_component(np.flipud(read_grey(path)) >= cfg.free_threshold)
    rows, cols = free.shape
    spec = GridSpec(0.0, 0.0, cfg.resolution_m, rows, cols)
    world = World(name=f"floorplan-{path.stem}", spec=spec, occupied=~free)

    # Every point within (clearance - START_CLEARANCE_M) of the most open cell keeps
    # START_CLEARANCE_M, and so does the straight path between any two of them.
    clearance = world.clearance_m - 0.5 * cfg.resolution_m
    best = np.unravel_index(np.argmax(clearance), clearance.shape)
    spacing = min(START_SPACING_M, float(clearance[best]) - START_CLEARANCE_M - cfg.resolution_m)
    if spacing <= 0:
        raise DataError(path, f"no free spot with {START_CLEARANCE_M} m clearance for a robot")
    x, y = spec.cell_to_world(np.array([best]))[0]
    offsets = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]]) * spacing
    starts = np.column_stack([offsets + np.array([x, y]), np.zeros(len(offsets))])
    return World(name=world.name, spec=spec, occupied=world.occupied, default_starts=starts)
