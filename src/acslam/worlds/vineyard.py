"""A vineyard: parallel rows of vine plants, headlands at both ends, a fence around.

Rows run along +x. Row ``i`` lies at ``y = i * row_spacing_m`` and its plants at
``x = j * plant_spacing_m`` for ``x`` in ``[0, row_length_m]`` (field frame). The fence
runs ``headland_m`` outside the field on every side, so the headlands at both row ends
and the strips beside the outer rows are as wide as a headland. The grid adds a small
margin outside the fence.
"""

from __future__ import annotations

import math

import numpy as np

from acslam.config import VineyardWorld
from acslam.grid import GridSpec
from acslam.worlds.world import World

FENCE_THICKNESS_M = 0.1
OUTER_MARGIN_M = 0.5
START_SPACING_M = 0.6
MAX_STARTS = 10


def plant_positions(cfg: VineyardWorld, rng: np.random.Generator) -> np.ndarray:
    """(P, 2) plant centres in the field frame, gaps removed and jitter applied."""
    per_row = math.floor(cfg.row_length_m / cfg.plant_spacing_m + 1e-9) + 1
    xs = np.arange(per_row) * cfg.plant_spacing_m
    ys = np.arange(cfg.row_count) * cfg.row_spacing_m
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    kept = rng.random(len(grid)) >= cfg.gap_probability
    jitter = rng.uniform(-cfg.jitter_m, cfg.jitter_m, size=grid.shape)
    return (grid + jitter)[kept]


def stamp_discs(occupied: np.ndarray, spec: GridSpec, centres: np.ndarray, radius_m: float) -> None:
    """Mark occupied every cell whose centre lies within ``radius_m`` of a centre."""
    if len(centres) == 0:
        return
    reach = math.ceil(radius_m / spec.resolution_m) + 1
    offsets = np.arange(-reach, reach + 1)
    d_row, d_col = (a.ravel() for a in np.meshgrid(offsets, offsets, indexing="ij"))
    base = spec.world_to_cell(centres)
    rows = base[:, :1] + d_row[None, :]
    cols = base[:, 1:] + d_col[None, :]
    cell_x = spec.origin_x_m + (cols + 0.5) * spec.resolution_m
    cell_y = spec.origin_y_m + (rows + 0.5) * spec.resolution_m
    inside = (cell_x - centres[:, :1]) ** 2 + (cell_y - centres[:, 1:]) ** 2 <= radius_m**2
    inside &= (rows >= 0) & (rows < spec.rows) & (cols >= 0) & (cols < spec.cols)
    occupied[rows[inside], cols[inside]] = True


def vineyard_spec(cfg: VineyardWorld) -> GridSpec:
    """The field, its headlands, the fence and the margin outside it."""
    field_width = (cfg.row_count - 1) * cfg.row_spacing_m
    border = cfg.headland_m + FENCE_THICKNESS_M + OUTER_MARGIN_M
    res = cfg.resolution_m
    cols = math.ceil((cfg.row_length_m + 2 * border) / res)
    rows = math.ceil((field_width + 2 * border) / res)
    return GridSpec(-border, -border, res, rows, cols)


def vineyard_world(cfg: VineyardWorld, rng: np.random.Generator) -> World:
    """Build the vineyard; starts form a column in the west headland facing the rows."""
    field_width = (cfg.row_count - 1) * cfg.row_spacing_m
    res = cfg.resolution_m
    spec = vineyard_spec(cfg)

    occupied = np.zeros(spec.shape, dtype=bool)
    fence_cells = math.ceil(FENCE_THICKNESS_M / res)
    (r0, c0), (r1, c1) = spec.world_to_cell(
        np.array(
            [
                [-cfg.headland_m, -cfg.headland_m],
                [cfg.row_length_m + cfg.headland_m, field_width + cfg.headland_m],
            ]
        )
    )
    occupied[r0 - fence_cells : r1 + fence_cells + 1, c0 - fence_cells : c1 + fence_cells + 1] = (
        True
    )
    occupied[r0 : r1 + 1, c0 : c1 + 1] = False
    fence = occupied.copy()
    plants = plant_positions(cfg, rng)
    stamp_discs(occupied, spec, plants, cfg.plant_radius_m)

    # A column of poses in the middle of the west headland, nearest the field's centre
    # line first, keeping 0.5 m from the fence.
    k = np.arange(2 * MAX_STARTS)
    offsets = np.where(k % 2 == 1, (k + 1) // 2, -(k // 2)) * START_SPACING_M
    offsets = offsets[np.abs(offsets) <= field_width / 2 + cfg.headland_m - 0.5][:MAX_STARTS]
    starts = np.column_stack(
        [
            np.full(len(offsets), -cfg.headland_m / 2),
            field_width / 2 + offsets,
            np.zeros(len(offsets)),
        ]
    )
    return World(
        name="vineyard",
        spec=spec,
        occupied=occupied,
        default_starts=starts,
        discs=np.column_stack([plants, np.full(len(plants), cfg.plant_radius_m)]),
        occupied_without_discs=fence,
    )
