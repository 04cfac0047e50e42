"""Tiny hand-built worlds for the simulator tests."""

from __future__ import annotations

import numpy as np

from acslam.grid import GridSpec
from acslam.worlds.world import World

RES_M = 0.05


def box_world(width_m: float, height_m: float, wall_cols: tuple[int, ...] = ()) -> World:
    """A rectangular room with a one-cell border wall and optional full-height walls.

    The room's inner faces are at x = RES_M, x = width_m - RES_M, y = RES_M,
    y = height_m - RES_M; a wall column c occupies x in [c * RES_M, (c + 1) * RES_M).
    """
    cols = round(width_m / RES_M)
    rows = round(height_m / RES_M)
    occupied = np.zeros((rows, cols), dtype=bool)
    occupied[0, :] = occupied[-1, :] = True
    occupied[:, 0] = occupied[:, -1] = True
    for c in wall_cols:
        occupied[:, c] = True
    return World("box", GridSpec(0.0, 0.0, RES_M, rows, cols), occupied)
