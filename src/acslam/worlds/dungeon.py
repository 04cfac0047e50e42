"""A dungeon: rectangular rooms joined by L-shaped corridors through doors.

Rooms are random non-overlapping rectangles, kept apart far enough for a corridor and
two walls to pass between them. Corridors follow a minimum spanning tree over the room
centres plus the shortest remaining edge (one loop, so the map has a cycle to close).
Every room gets a wall ring of ``wall_thickness_m``; where a corridor's centre line
crosses a ring, a door of ``door_width_m`` is cut. Everything else is occupied, so the
grid border is the outer wall. Layouts whose rooms a robot could not all reach (a
corridor squeezed along a wall) are drawn again.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage
from scipy.sparse.csgraph import minimum_spanning_tree
from scipy.spatial.distance import cdist

from acslam.config import DungeonWorld
from acslam.errors import ConfigError
from acslam.grid import GridSpec
from acslam.worlds.world import World

START_SPACING_M = 0.6
START_CLEARANCE_M = 0.3
CHECK_ROBOT_RADIUS_M = 0.2
"""Radius of the robot that must reach every room (above a TurtleBot3's 0.105 m)."""
MAX_LAYOUT_TRIES = 50
PLACEMENT_TRIES_PER_ROOM = 300


def place_rooms(cfg: DungeonWorld, rng: np.random.Generator) -> np.ndarray:
    """(R, 4) room interiors ``[x0, y0, x1, y1]``, largest first, at least one room."""
    gap = cfg.corridor_width_m + 2 * cfg.wall_thickness_m
    margin = 2 * cfg.wall_thickness_m
    rooms: list[np.ndarray] = []
    for _ in range(cfg.room_count * PLACEMENT_TRIES_PER_ROOM):
        if len(rooms) == cfg.room_count:
            break
        size = rng.uniform(cfg.room_size_min_m, cfg.room_size_max_m, size=2)
        size = np.minimum(size, [cfg.width_m - 2 * margin, cfg.height_m - 2 * margin])
        low = rng.uniform(margin, [cfg.width_m - margin - size[0], cfg.height_m - margin - size[1]])
        room = np.concatenate([low, low + size])
        if rooms:
            placed = np.array(rooms)
            apart = (
                (room[0] >= placed[:, 2] + gap)
                | (placed[:, 0] >= room[2] + gap)
                | (room[1] >= placed[:, 3] + gap)
                | (placed[:, 1] >= room[3] + gap)
            )
            if not apart.all():
                continue
        rooms.append(room)
    rooms_arr = np.array(rooms)
    area = (rooms_arr[:, 2] - rooms_arr[:, 0]) * (rooms_arr[:, 3] - rooms_arr[:, 1])
    return rooms_arr[np.argsort(-area, kind="stable")]


def corridor_edges(centres: np.ndarray) -> list[tuple[int, int]]:
    """Minimum spanning tree over the centres plus the shortest non-tree edge."""
    if len(centres) < 2:
        return []
    dist = cdist(centres, centres)
    tree = minimum_spanning_tree(dist).toarray() > 0
    tree |= tree.T
    edges = [(int(a), int(b)) for a, b in zip(*np.nonzero(np.triu(tree)), strict=True)]
    spare = np.triu(~tree, k=1)
    if spare.any():
        a, b = np.unravel_index(np.argmin(np.where(spare, dist, np.inf)), dist.shape)
        edges.append((int(a), int(b)))
    return edges


def _cells(spec: GridSpec, x0: float, y0: float, x1: float, y1: float) -> tuple[slice, slice]:
    """Row/column slices of the cells a rectangle covers, clipped to the grid."""
    res = spec.resolution_m
    c0, c1 = (min(max(math.floor(v / res + 0.5), 0), spec.cols) for v in (x0, x1))
    r0, r1 = (min(max(math.floor(v / res + 0.5), 0), spec.rows) for v in (y0, y1))
    return slice(r0, r1), slice(c0, c1)


def rasterise(
    cfg: DungeonWorld,
    spec: GridSpec,
    rooms: np.ndarray,
    edges: list[tuple[int, int]],
    rng: np.random.Generator,
) -> np.ndarray:
    """Occupied mask of rooms, corridors, walls and doors."""
    free = np.zeros(spec.shape, dtype=bool)
    centre_line = np.zeros(spec.shape, dtype=bool)
    half = cfg.corridor_width_m / 2
    line = spec.resolution_m / 2
    centres = (rooms[:, :2] + rooms[:, 2:]) / 2
    for a, b in edges:
        (xa, ya), (xb, yb) = centres[a], centres[b]
        # horizontal leg first, or vertical leg first
        corner = (xb, ya) if rng.random() < 0.5 else (xa, yb)
        for (x0, y0), (x1, y1) in (((xa, ya), corner), (corner, (xb, yb))):
            lo_x, hi_x, lo_y, hi_y = min(x0, x1), max(x0, x1), min(y0, y1), max(y0, y1)
            free[_cells(spec, lo_x - half, lo_y - half, hi_x + half, hi_y + half)] = True
            centre_line[_cells(spec, lo_x - line, lo_y - line, hi_x + line, hi_y + line)] = True

    rings = np.zeros(spec.shape, dtype=bool)
    t = cfg.wall_thickness_m
    for x0, y0, x1, y1 in rooms:
        rings[_cells(spec, x0 - t, y0 - t, x1 + t, y1 + t)] = True
    interiors = np.zeros(spec.shape, dtype=bool)
    for x0, y0, x1, y1 in rooms:
        interiors[_cells(spec, x0, y0, x1, y1)] = True
    rings &= ~interiors

    door_cells = max(1, round(cfg.door_width_m / spec.resolution_m))
    doors = ndimage.binary_dilation(
        centre_line & rings, structure=np.ones((door_cells, door_cells), dtype=bool)
    )
    free &= ~rings
    free |= (doors & rings) | interiors
    return ~free


def dungeon_spec(cfg: DungeonWorld) -> GridSpec:
    res = cfg.resolution_m
    return GridSpec(0.0, 0.0, res, round(cfg.height_m / res), round(cfg.width_m / res))


def dungeon_world(cfg: DungeonWorld, rng: np.random.Generator) -> World:
    """Build a dungeon whose rooms all connect; starts fill the largest room's centre."""
    res = cfg.resolution_m
    spec = dungeon_spec(cfg)
    for _ in range(MAX_LAYOUT_TRIES):
        rooms = place_rooms(cfg, rng)
        centres = (rooms[:, :2] + rooms[:, 2:]) / 2
        occupied = rasterise(cfg, spec, rooms, corridor_edges(centres), rng)
        world = World(name="dungeon", spec=spec, occupied=occupied)
        reach = world.reachable_free(*centres[0], CHECK_ROBOT_RADIUS_M)
        if reach[tuple(spec.world_to_cell(centres).T)].all():
            break
    else:
        raise ConfigError(
            None,
            "world",
            f"no dungeon layout with every room connected in {MAX_LAYOUT_TRIES} tries: "
            "use fewer or smaller rooms, or a larger area",
        )

    # A grid of poses over the largest room, nearest its centre first.
    x0, y0, x1, y1 = rooms[0]
    inset = START_CLEARANCE_M + res
    axes = []
    for lo, hi in ((x0 + inset, x1 - inset), (y0 + inset, y1 - inset)):
        count = math.floor((hi - lo) / START_SPACING_M + 1e-9) + 1
        axes.append((lo + hi) / 2 + (np.arange(count) - (count - 1) / 2) * START_SPACING_M)
    xy = np.stack(np.meshgrid(*axes), axis=-1).reshape(-1, 2)
    xy = xy[np.argsort(np.linalg.norm(xy - centres[0], axis=1), kind="stable")]
    starts = np.column_stack([xy, np.zeros(len(xy))])
    return World(name="dungeon", spec=spec, occupied=occupied, default_starts=starts)
