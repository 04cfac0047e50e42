"""The lab environments of thesis §5.2, rebuilt from the text and tables of chapter 5.

The thesis shows the four PIC4SeR test arenas only as photos, so the layouts below are
ours; they keep what the text states: the number of frontiers visible from the starts,
the explorable area (tables 5.1-5.9 report about 65 m² for experiments 1-4 and about
100 m² for experiment 5), and the 40 m x 40 m grid at 0.05 m. Everything is occupied but
the designed free space, which sits around the grid centre (20, 20). Spaces are
axis-aligned rectangles separated by 0.15 m walls (an uncarved strip); an opening is a
rectangle carved through such a wall. The robots start ~0.7 m apart in the start area.
Each layout's ``summary`` says what it holds; the experiments' summary tables print it
beside the thesis's own description.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from acslam.config import ThesisWorld
from acslam.grid import GridSpec
from acslam.worlds.world import World

GRID_SIZE_M = 40.0
WALL_M = 0.15
CORRIDOR_M = 1.2

Rect = tuple[float, float, float, float]
"""``(x0, y0, x1, y1)`` in metres, x0 < x1 and y0 < y1."""


@dataclass(frozen=True)
class ThesisLayout:
    """A layout in metres: free rectangles, the start area, its openings, the starts, and
    one sentence saying what it holds."""

    spaces: tuple[Rect, ...]
    start_area: Rect
    start_openings: tuple[Rect, ...]
    starts: tuple[tuple[float, float, float], ...]
    summary: str


def _corridor(points: list[tuple[float, float]], width: float = CORRIDOR_M) -> list[Rect]:
    """Rectangles of an axis-aligned polyline corridor, ends extended by half the width."""
    half = width / 2
    rects = []
    for (xa, ya), (xb, yb) in itertools.pairwise(points):
        rects.append(
            (min(xa, xb) - half, min(ya, yb) - half, max(xa, xb) + half, max(ya, yb) + half)
        )
    return rects


def _row_starts(
    y: float, theta: float, x_mid: float = 20.0
) -> tuple[tuple[float, float, float], ...]:
    """Three poses 0.7 m apart along x, the middle one first (the single-robot start)."""
    return ((x_mid, y, theta), (x_mid - 0.7, y, theta), (x_mid + 0.7, y, theta))


def _layout(
    start: Rect,
    openings: tuple[Rect, ...],
    rooms: tuple[Rect, ...],
    starts: tuple[tuple[float, float, float], ...],
    summary: str,
) -> ThesisLayout:
    """A layout whose robots start in ``start``, which ``openings`` join to the ``rooms``."""
    return ThesisLayout(
        spaces=(start, *openings, *rooms),
        start_area=start,
        start_openings=openings,
        starts=starts,
        summary=summary,
    )


def _exp1() -> ThesisLayout:
    start = (18.0, 16.0, 22.0, 20.0)
    door = (19.5, 20.0, 20.5, 20.15)
    corridor = (15.0, 20.15, 25.0, 21.65)
    west, east = (10.85, 19.0, 14.85, 23.5), (25.15, 19.0, 29.15, 23.5)
    west_door, east_door = (14.85, 20.4, 15.0, 21.4), (25.0, 20.4, 25.15, 21.4)
    return _layout(
        start,
        (door,),
        (corridor, west, east, west_door, east_door),
        _row_starts(17.5, math.pi / 2),
        "a 4 m x 4 m start room whose only opening (north) leads into a 10 m corridor; its "
        "two ends open into a west and an east room, the two frontiers found later",
    )


def _exp2() -> ThesisLayout:
    start = (18.0, 17.0, 22.0, 21.0)
    doors = ((17.85, 18.5, 18.0, 19.5), (19.5, 21.0, 20.5, 21.15), (22.0, 18.5, 22.15, 19.5))
    rooms = ((13.85, 17.0, 17.85, 21.0), (18.0, 21.15, 22.0, 25.15), (22.15, 17.0, 26.15, 21.0))
    return _layout(
        start,
        doors,
        rooms,
        _row_starts(18.2, math.pi / 2),
        "a 4 m x 4 m start room with three symmetric doors (west, north, east), each into a "
        "4 m x 4 m room: three initial frontiers, one per robot",
    )


def _exp3() -> ThesisLayout:
    start = (18.0, 18.0, 22.0, 22.0)
    doors = (
        (17.85, 19.5, 18.0, 20.5),
        (19.5, 22.0, 20.5, 22.15),
        (22.0, 19.5, 22.15, 20.5),
        (19.5, 17.85, 20.5, 18.0),
    )
    north, south = (18.0, 22.15, 22.0, 25.15), (18.0, 14.85, 22.0, 17.85)
    west_corridor, east_corridor = (14.85, 19.4, 17.85, 20.6), (22.15, 19.4, 25.15, 20.6)
    west_room, east_room = (11.7, 18.5, 14.7, 21.5), (25.3, 18.5, 28.3, 21.5)
    west_door, east_door = (14.7, 19.5, 14.85, 20.5), (25.15, 19.5, 25.3, 20.5)
    return _layout(
        start,
        doors,
        (
            north,
            south,
            west_corridor,
            east_corridor,
            west_room,
            east_room,
            west_door,
            east_door,
        ),
        _row_starts(20.9, 0.0),
        "a 4 m x 4 m start room with four doors: rooms to the north and south, and 3 m "
        "corridors west and east that end in 3 m x 3 m rooms",
    )


def _exp4() -> ThesisLayout:
    start = (18.0, 18.5, 22.0, 21.5)
    openings = (
        (17.85, 19.5, 18.0, 20.5),  # west
        (22.0, 19.5, 22.15, 20.5),  # east
        (18.5, 21.5, 19.5, 21.65),  # north-west
        (20.5, 21.5, 21.5, 21.65),  # north-east
        (19.5, 18.35, 20.5, 18.5),  # south
    )
    branches = [
        # west: out, up the west side, back east to meet the north-west branch (a loop)
        [(17.25, 20.0), (14.6, 20.0), (14.6, 25.0), (19.0, 25.0)],
        # north-west: up, then a dead end to the north
        [(19.0, 22.25), (19.0, 26.8)],
        # north-east: up, east, then north to a dead end
        [(21.0, 22.25), (21.0, 23.6), (24.4, 23.6), (24.4, 25.8)],
        # east: out, down the east side, back west under the start room
        [(22.75, 20.0), (25.6, 20.0), (25.6, 15.3), (23.6, 15.3)],
        # south: down, then west to a dead end
        [(20.0, 17.75), (20.0, 16.9), (15.4, 16.9), (15.4, 14.6)],
    ]
    corridors = [rect for branch in branches for rect in _corridor(branch)]
    return _layout(
        start,
        openings,
        tuple(corridors),
        _row_starts(19.6, math.pi / 2),
        "a 4 m x 3 m start room with five openings into a labyrinth of 1.2 m corridors with "
        "turns, dead ends and one loop (the two north-west branches meet)",
    )


def _exp5() -> ThesisLayout:
    lab = (16.5, 20.0, 23.5, 24.5)
    lab_doors = ((17.5, 19.85, 18.5, 20.0), (21.5, 19.85, 22.5, 20.0))
    corridor = (12.0, 18.35, 28.0, 19.85)
    offices = ((12.0, 15.2, 15.5, 18.2), (15.65, 15.2, 19.15, 18.2), (19.3, 15.2, 22.8, 18.2))
    office_doors = (
        (13.25, 18.2, 14.25, 18.35),
        (16.9, 18.2, 17.9, 18.35),
        (20.55, 18.2, 21.55, 18.35),
    )
    store = (28.15, 16.0, 31.15, 19.5)
    store_door = (28.0, 18.6, 28.15, 19.6)
    rooms = (corridor, *offices, *office_doors, store, store_door)
    return _layout(
        lab,
        lab_doors,
        rooms,
        _row_starts(22.0, -math.pi / 2),
        "a floor: a 7 m x 4.5 m lab (the start area) with two doors onto a 16 m corridor, "
        "three offices across it and a store room at its east end",
    )


LAYOUTS = {1: _exp1, 2: _exp2, 3: _exp3, 4: _exp4, 5: _exp5}


def thesis_layout(experiment: int) -> ThesisLayout:
    """The layout of thesis experiment ``experiment`` (1-5), in metres."""
    return LAYOUTS[experiment]()


def rect_cells(rect: Rect, resolution_m: float) -> tuple[slice, slice]:
    """Row and column slices of the cells a rectangle covers (edges rounded to cells)."""
    x0, y0, x1, y1 = (math.floor(v / resolution_m + 0.5) for v in rect)
    return slice(y0, y1), slice(x0, x1)


def thesis_spec(cfg: ThesisWorld) -> GridSpec:
    """The 40 m x 40 m grid every thesis layout is drawn on."""
    size = round(GRID_SIZE_M / cfg.resolution_m)
    return GridSpec(0.0, 0.0, cfg.resolution_m, size, size)


def thesis_world(cfg: ThesisWorld) -> World:
    """Rasterise the layout of ``cfg.experiment`` onto a 40 m x 40 m occupied grid."""
    layout = thesis_layout(cfg.experiment)
    spec = thesis_spec(cfg)
    occupied = np.ones(spec.shape, dtype=bool)
    for rect in layout.spaces:
        occupied[rect_cells(rect, cfg.resolution_m)] = False
    return World(
        name=f"thesis-exp{cfg.experiment}",
        spec=spec,
        occupied=occupied,
        default_starts=np.array(layout.starts, dtype=float),
    )
