"""Global correlative matching of a point set against a map, by branch and bound.

Where does a scan, or a whole map of another robot, lie in this map, with no guess at
all? ICP (:mod:`acslam.mapping.scan_matching`) needs a guess near the answer. A
correlative search (Olson 2009) scores every pose of a grid of poses instead: each point
is looked up in a likelihood field of the map (``exp(-d^2 / 2 sigma^2)``, ``d`` the
distance to the nearest occupied cell), and a pose scores the mean over its points. The
grid is every cell of the search window at every angle step, so the answer is the best
pose to within a cell and an angle step, never a local optimum.

Branch and bound makes that exact search fast, as Cartographer's global matcher does
(Hess et al. 2016, §V): level ``h`` of a pyramid holds, at each cell, the largest
likelihood of the ``2^h x 2^h`` block of cells starting there, so the score of a pose
looked up at level ``h`` bounds the score of every one of the ``4^h`` finer poses it
stands for. The search descends the best bounds first and drops a block whose bound is
no better than the best pose found, so it returns the very pose the exhaustive search
returns (:func:`exhaustive_match` is that reference) at a small part of the cost.

The angle step follows Cartographer: the angle that moves the farthest point by one
cell, ``acos(1 - r^2 / 2 d^2)``, with the points centred on their centroid so ``d`` is
as small as it can be.

Poses are ``[x, y, theta]`` (m, rad): the pose in the map's frame of the frame the
points are given in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from acslam.geometry import wrap_angles
from acslam.grid import FREE, OCCUPIED, GridSpec


@dataclass(frozen=True)
class LikelihoodPyramid:
    """The map's likelihood field and its branch-and-bound levels.

    ``levels[h, pad + row, pad + col]`` is the largest likelihood of the ``2^h x 2^h``
    cells from ``(row, col)`` up (:func:`block_maxima`); level 0 is the field itself.
    """

    spec: GridSpec
    levels: np.ndarray

    @property
    def depth(self) -> int:
        return len(self.levels) - 1

    @property
    def pad(self) -> int:
        return (1 << self.depth) - 1

    def likelihood_at(self, points_m: np.ndarray) -> np.ndarray:
        """The field at each (N, 2) point; 0 beyond the grid."""
        cells = self.spec.world_to_cell(points_m)
        inside = self.spec.contains(cells)
        out = np.zeros(len(cells))
        out[inside] = self.levels[0, self.pad + cells[inside, 0], self.pad + cells[inside, 1]]
        return out

    @classmethod
    def from_occupancy(
        cls, values: np.ndarray, spec: GridSpec, sigma_m: float, depth: int
    ) -> LikelihoodPyramid:
        """From OccupancyGrid values. Points land on surfaces: occupied cells beside a
        free one (a solid block's inside, as a ground-truth map has, is never hit)."""
        surface = surface_cells(values)
        if surface.any():
            distance_m = ndimage.distance_transform_edt(~surface) * spec.resolution_m
            field = np.exp(-0.5 * (distance_m / sigma_m) ** 2).astype(np.float32)
        else:
            field = np.zeros(surface.shape, dtype=np.float32)
        return cls(spec, block_maxima(field, depth))


def surface_cells(values: np.ndarray) -> np.ndarray:
    """Occupied cells with a free 4-neighbour: where beams end. A SLAM map's wall is a
    band of cells whose far side borders unknown space, and is as thick as the map's
    noise made it: counting that side too biased two maps' match by a cell or two."""
    values = np.asarray(values)
    free_beside = ndimage.binary_dilation(values == FREE, ndimage.generate_binary_structure(2, 1))
    return (values == OCCUPIED) & free_beside


def block_maxima(field: np.ndarray, depth: int) -> np.ndarray:
    """(depth + 1, P + rows, P + cols), P = 2^depth - 1 leading cells of padding: level h
    at (P + r, P + c) = max of ``field[r:r+2^h, c:c+2^h]``, for r and c from -P on (cells
    beyond the grid count 0: fields are >= 0). A block that starts before the grid still
    overlaps it, so its bound must hold there too.

    A block of side 2^h is four blocks of side 2^(h-1), so each level is the maximum of
    shifted copies of the one below.
    """
    pad = (1 << depth) - 1
    rows, cols = field.shape
    levels = np.zeros((depth + 1, pad + rows, pad + cols), dtype=np.float32)
    levels[0, pad:, pad:] = field
    for h in range(1, depth + 1):
        half = 1 << (h - 1)
        level = levels[h - 1].copy()
        level[:-half] = np.maximum(level[:-half], level[half:])
        level[:, :-half] = np.maximum(level[:, :-half], level[:, half:])
        levels[h] = level
    return levels


@dataclass(frozen=True)
class SearchWindow:
    """The poses searched: the points' pivot within ``half_size_m`` (x, y) of
    ``center_xy_m`` and the heading within ``half_angle_rad`` of ``center_theta_rad``
    (pi: every heading). The search turns the points about the pivot, so a window on the
    pivot is the same at every heading. The pivot is the points' centroid (the fewest
    angle steps), or ``pivot_m``, a point of the points' frame whose place is known to
    within the window: where a teammate saw the robot that stands there (:meth:`pinned`).
    """

    center_xy_m: tuple[float, float]
    half_size_m: tuple[float, float]
    center_theta_rad: float = 0.0
    half_angle_rad: float = math.pi
    pivot_m: tuple[float, float] | None = None

    @classmethod
    def covering(cls, spec: GridSpec, points_m: np.ndarray) -> SearchWindow:
        """Every pose at which the points could overlap the map at all."""
        points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)
        reach_m = float(np.max(np.linalg.norm(points_m - points_m.mean(axis=0), axis=1)))
        width_m, height_m = spec.width_m, spec.height_m
        return cls(
            (spec.origin_x_m + width_m / 2, spec.origin_y_m + height_m / 2),
            (width_m / 2 + reach_m, height_m / 2 + reach_m),
        )

    @classmethod
    def around(
        cls, pose: np.ndarray, points_m: np.ndarray, half_size_m: float, half_angle_rad: float
    ) -> SearchWindow:
        """The poses within ``half_size_m`` and ``half_angle_rad`` of a guessed ``pose``."""
        centroid = np.asarray(points_m, dtype=float).reshape(-1, 2).mean(axis=0)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        x = pose[0] + c * centroid[0] - s * centroid[1]
        y = pose[1] + s * centroid[0] + c * centroid[1]
        return cls((x, y), (half_size_m, half_size_m), float(pose[2]), half_angle_rad)

    @classmethod
    def pinned(
        cls, pivot_m: np.ndarray, center_xy_m: np.ndarray, half_size_m: float
    ) -> SearchWindow:
        """The poses, at every heading, that put the points' ``pivot_m`` within
        ``half_size_m`` of ``center_xy_m``."""
        return cls(
            (float(center_xy_m[0]), float(center_xy_m[1])),
            (half_size_m, half_size_m),
            pivot_m=(float(pivot_m[0]), float(pivot_m[1])),
        )


@dataclass(frozen=True)
class Match:
    """The best pose found, its score (mean likelihood of the points, 0-1), and the
    search's grid: ``angle_step_rad`` and the cell size say how close to the truth it is."""

    pose: np.ndarray
    score: float
    angle_step_rad: float
    resolution_m: float


@dataclass(frozen=True)
class _Candidates:
    """The discretised search: per angle, the points' cells at offset (0, 0)."""

    angles_rad: np.ndarray
    cells: np.ndarray  # (angles, points, 2) [row, col], int64
    offsets: tuple[int, int]  # columns, rows of offsets
    corner_xy_m: np.ndarray  # the pivot's position at offset (0, 0)
    pivot_m: np.ndarray
    angle_step_rad: float


def angle_step_rad(resolution_m: float, reach_m: float) -> float:
    """The rotation that moves a point ``reach_m`` from the centre by one cell."""
    if reach_m <= resolution_m:
        return math.pi / 4
    return math.acos(1.0 - resolution_m**2 / (2.0 * reach_m**2))


def _candidates(points_m: np.ndarray, spec: GridSpec, window: SearchWindow) -> _Candidates:
    points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)
    pivot = points_m.mean(axis=0) if window.pivot_m is None else np.array(window.pivot_m)
    centred = points_m - pivot
    reach_m = float(np.max(np.linalg.norm(centred, axis=1)))
    step = angle_step_rad(spec.resolution_m, reach_m)
    if window.half_angle_rad >= math.pi:
        count = max(1, math.ceil(2 * math.pi / step))
        step = 2 * math.pi / count
        angles = window.center_theta_rad + step * np.arange(count)
    else:
        half_count = math.ceil(window.half_angle_rad / step)
        angles = window.center_theta_rad + step * np.arange(-half_count, half_count + 1)
    res = spec.resolution_m
    columns = max(1, math.ceil(2 * window.half_size_m[0] / res) + 1)
    rows = max(1, math.ceil(2 * window.half_size_m[1] / res) + 1)
    # At offset (0, 0) the pivot stands at the window's corner.
    corner = np.asarray(window.center_xy_m, dtype=float) - np.asarray(window.half_size_m)
    cos, sin = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x = cos * centred[None, :, 0] - sin * centred[None, :, 1] + corner[0]
    y = sin * centred[None, :, 0] + cos * centred[None, :, 1] + corner[1]
    cells = np.empty((len(angles), len(centred), 2), dtype=np.int64)
    cells[..., 0] = np.floor((y - spec.origin_y_m) / res).astype(np.int64)
    cells[..., 1] = np.floor((x - spec.origin_x_m) / res).astype(np.int64)
    return _Candidates(angles, cells, (columns, rows), corner, pivot, step)


def _pose(candidates: _Candidates, k: int, dx: int, dy: int, resolution_m: float) -> np.ndarray:
    """The frame pose whose centred points land at angle ``k``, offset (dx, dy)."""
    theta = float(candidates.angles_rad[k])
    pivot_xy = candidates.corner_xy_m + resolution_m * np.array([dx, dy], dtype=float)
    c, s = math.cos(theta), math.sin(theta)
    cx, cy = candidates.pivot_m
    origin = pivot_xy - np.array([c * cx - s * cy, s * cx + c * cy])
    return np.array([origin[0], origin[1], math.atan2(s, c)])


@numba.njit(cache=True, nogil=True)
def _score(level: np.ndarray, cells: np.ndarray, dx: int, dy: int, pad: int) -> float:
    rows, cols = level.shape
    total = 0.0
    for i in range(cells.shape[0]):
        r = cells[i, 0] + dy + pad
        c = cells[i, 1] + dx + pad
        if 0 <= r < rows and 0 <= c < cols:
            total += level[r, c]
    return total / cells.shape[0]


@numba.njit(cache=True, nogil=True)
def _excluded(k: int, dx: int, dy: int, zones: np.ndarray, angles: int) -> bool:
    """Whether the leaf (k, dx, dy) lies in a zone (k0, dx0, dy0, half-width in angle
    steps, half-width in cells) of ``zones``; ``angles`` is the ring size of k."""
    for z in range(zones.shape[0]):
        dk = abs(k - zones[z, 0])
        dk = min(dk, angles - dk)
        if (
            dk <= zones[z, 3]
            and abs(dx - zones[z, 1]) <= zones[z, 4]
            and abs(dy - zones[z, 2]) <= zones[z, 4]
        ):
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _branch_and_bound(
    levels: np.ndarray,
    cells: np.ndarray,
    columns: int,
    rows: int,
    min_score: float,
    zones: np.ndarray,
    wraps: bool,
) -> tuple[float, int, int, int]:
    """Best (score, k, dx, dy) over the leaves outside ``zones`` scoring above
    ``min_score`` (k = -1 if none does)."""
    depth = levels.shape[0] - 1
    pad = (1 << depth) - 1
    angles = cells.shape[0]
    ring = angles if wraps else 10**9
    top = 1 << depth
    per_angle = ((columns + top - 1) // top) * ((rows + top - 1) // top)
    count = angles * per_angle
    node_k = np.empty(count + 4 * depth + 4, dtype=np.int64)
    node_x = np.empty_like(node_k)
    node_y = np.empty_like(node_k)
    node_h = np.empty_like(node_k)
    node_s = np.empty(count + 4 * depth + 4, dtype=np.float64)
    start_s = np.empty(count, dtype=np.float64)
    start_k = np.empty(count, dtype=np.int64)
    start_x = np.empty(count, dtype=np.int64)
    start_y = np.empty(count, dtype=np.int64)
    n = 0
    for k in range(angles):
        for dy in range(0, rows, top):
            for dx in range(0, columns, top):
                start_s[n] = _score(levels[depth], cells[k], dx, dy, pad)
                start_k[n], start_x[n], start_y[n] = k, dx, dy
                n += 1
    order = np.argsort(start_s, kind="mergesort")  # ascending: the best ends on top
    size = 0
    for j in range(n):
        i = order[j]
        node_k[size], node_x[size], node_y[size] = start_k[i], start_x[i], start_y[i]
        node_h[size], node_s[size] = depth, start_s[i]
        size += 1
    best_s, best_k, best_x, best_y = min_score, -1, -1, -1
    child_s = np.empty(4)
    child_x = np.empty(4, dtype=np.int64)
    child_y = np.empty(4, dtype=np.int64)
    while size > 0:
        size -= 1
        k, dx, dy, h, s = node_k[size], node_x[size], node_y[size], node_h[size], node_s[size]
        if s <= best_s:
            continue
        if h == 0:
            if not _excluded(k, dx, dy, zones, ring):
                best_s, best_k, best_x, best_y = s, k, dx, dy
            continue
        half = 1 << (h - 1)
        m = 0
        for j in range(2):
            for i in range(2):
                cx, cy = dx + i * half, dy + j * half
                if cx < columns and cy < rows:
                    child_x[m], child_y[m] = cx, cy
                    child_s[m] = _score(levels[h - 1], cells[k], cx, cy, pad)
                    m += 1
        idx = np.argsort(child_s[:m], kind="mergesort")
        for j in range(m):
            i = idx[j]
            node_k[size], node_x[size], node_y[size] = k, child_x[i], child_y[i]
            node_h[size], node_s[size] = h - 1, child_s[i]
            size += 1
    return best_s, best_k, best_x, best_y


@numba.njit(cache=True, nogil=True)
def _exhaustive(
    field: np.ndarray,
    pad: int,
    cells: np.ndarray,
    columns: int,
    rows: int,
    zones: np.ndarray,
    wraps: bool,
) -> tuple[float, int, int, int]:
    angles = cells.shape[0]
    ring = angles if wraps else 10**9
    best_s, best_k, best_x, best_y = -1.0, -1, -1, -1
    for k in range(angles):
        for dy in range(rows):
            for dx in range(columns):
                if _excluded(k, dx, dy, zones, ring):
                    continue
                s = _score(field, cells[k], dx, dy, pad)
                if s > best_s:
                    best_s, best_k, best_x, best_y = s, k, dx, dy
    return best_s, best_k, best_x, best_y


@numba.njit(cache=True, nogil=True)
def _best_per_angle(
    field: np.ndarray, pad: int, cells: np.ndarray, columns: int, rows: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per angle k, the best leaf's (score, dx, dy) over every offset: each point adds its
    block of ``rows x columns`` field cells to the offsets' sums (rows read in a run,
    where :func:`_score` reads one scattered cell per point and leaf). The sums add the
    same values in the same order as :func:`_score`, so the scores are its scores."""
    angles, count = cells.shape[0], cells.shape[1]
    field_rows, field_cols = field.shape
    best_s = np.empty(angles)
    best_x = np.empty(angles, dtype=np.int64)
    best_y = np.empty(angles, dtype=np.int64)
    sums = np.empty((rows, columns))
    for k in range(angles):
        sums[:] = 0.0
        for i in range(count):
            r0 = cells[k, i, 0] + pad
            c0 = cells[k, i, 1] + pad
            if r0 >= 0 and c0 >= 0 and r0 + rows <= field_rows and c0 + columns <= field_cols:
                for dy in range(rows):  # the whole block inside: no test per cell
                    for dx in range(columns):
                        sums[dy, dx] += field[r0 + dy, c0 + dx]
                continue
            for dy in range(rows):
                r = r0 + dy
                if 0 <= r < field_rows:
                    for dx in range(columns):
                        c = c0 + dx
                        if 0 <= c < field_cols:
                            sums[dy, dx] += field[r, c]
        s, x, y = -1.0, -1, -1
        for dy in range(rows):
            for dx in range(columns):
                if sums[dy, dx] > s:
                    s, x, y = sums[dy, dx], dx, dy
        best_s[k], best_x[k], best_y[k] = s / count, x, y
    return best_s, best_x, best_y


def _leaf(candidates: _Candidates, pose: np.ndarray, res: float) -> tuple[int, int, int]:
    """The (angle, dx, dy) of the search's grid nearest ``pose``."""
    theta = float(pose[2])
    c, s = math.cos(theta), math.sin(theta)
    cx, cy = candidates.pivot_m
    pivot_xy = pose[:2] + np.array([c * cx - s * cy, s * cx + c * cy])
    dx, dy = np.rint((pivot_xy - candidates.corner_xy_m) / res).astype(int)
    k = int(np.argmin(np.abs(wrap_angles(candidates.angles_rad - theta))))
    return k, int(dx), int(dy)


def _zones(
    candidates: _Candidates, around: list[Match], radius_m: float, angle_rad: float, res: float
) -> np.ndarray:
    """(Z, 5) zones (k0, dx0, dy0, rk, rxy) of the leaves near each pose of ``around``."""
    zones = np.zeros((len(around), 5), dtype=np.int64)
    angle_steps = math.floor(angle_rad / candidates.angle_step_rad)
    for z, match in enumerate(around):
        zones[z] = (*_leaf(candidates, match.pose, res), angle_steps, math.floor(radius_m / res))
    return zones


SEED_POINTS = 400
"""Above this many points, a search first runs on every n-th point (about this many), and
its answer, scored on all points, is the bound the full search starts from."""


def best_match(
    points_m: np.ndarray,
    pyramid: LikelihoodPyramid,
    window: SearchWindow,
    min_score: float = 0.0,
    excluded: tuple[Match, ...] = (),
    excluded_radius_m: float = 0.0,
    excluded_angle_rad: float = 0.0,
) -> Match | None:
    """The best pose of the points' frame in the window that scores above ``min_score``
    (None if there is none).

    Poses within ``excluded_radius_m`` (per axis, of the pivot) and
    ``excluded_angle_rad`` of one in ``excluded`` are left out: the best *other* mode,
    which says whether the first one is unique.
    """
    return _search(
        points_m, pyramid, window, min_score, excluded, excluded_radius_m, excluded_angle_rad,
        exhaustive=False,
    )  # fmt: skip


def exhaustive_match(
    points_m: np.ndarray,
    pyramid: LikelihoodPyramid,
    window: SearchWindow,
    excluded: tuple[Match, ...] = (),
    excluded_radius_m: float = 0.0,
    excluded_angle_rad: float = 0.0,
) -> Match | None:
    """Every pose of the same grid scored on the field itself: the reference
    :func:`best_match` must equal, and the benchmark's baseline."""
    return _search(
        points_m, pyramid, window, -1.0, excluded, excluded_radius_m, excluded_angle_rad,
        exhaustive=True,
    )  # fmt: skip


def _search(
    points_m: np.ndarray,
    pyramid: LikelihoodPyramid,
    window: SearchWindow,
    min_score: float,
    excluded: tuple[Match, ...],
    excluded_radius_m: float,
    excluded_angle_rad: float,
    exhaustive: bool,
) -> Match | None:
    points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)
    candidates = _candidates(points_m, pyramid.spec, window)
    res = pyramid.spec.resolution_m
    zones = _zones(candidates, list(excluded), excluded_radius_m, excluded_angle_rad, res)
    wraps = window.half_angle_rad >= math.pi
    ring = len(candidates.angles_rad) if wraps else 10**9
    if exhaustive:
        score, k, dx, dy = _exhaustive(
            pyramid.levels[0], pyramid.pad, candidates.cells, *candidates.offsets, zones, wraps
        )
        return None if k < 0 else _match(candidates, k, dx, dy, score, res)
    # Branch and bound prunes by the best leaf found so far, and finds a good one late
    # when it starts from nothing: a search on a subsample gives a leaf whose score on
    # every point is a true lower bound of the answer to start from (it stays exact).
    seed = None
    if len(points_m) > SEED_POINTS:
        every = math.ceil(len(points_m) / SEED_POINTS)
        rough = _search(
            points_m[::every], pyramid, window, 0.0, excluded, excluded_radius_m,
            excluded_angle_rad, exhaustive=False,
        )  # fmt: skip
        if rough is not None:
            k, dx, dy = _leaf(candidates, rough.pose, res)
            columns, rows = candidates.offsets
            if 0 <= dx < columns and 0 <= dy < rows and not _excluded(k, dx, dy, zones, ring):
                leaf_score = _score(pyramid.levels[0], candidates.cells[k], dx, dy, pyramid.pad)
                if leaf_score > min_score:
                    seed, min_score = (k, dx, dy, leaf_score), leaf_score
    score, k, dx, dy = _branch_and_bound(
        pyramid.levels, candidates.cells, *candidates.offsets, min_score, zones, wraps
    )
    if k < 0:
        if seed is None:
            return None
        k, dx, dy, score = seed  # no leaf beats the seed: it is the answer
    return _match(candidates, k, dx, dy, score, res)


def _match(candidates: _Candidates, k: int, dx: int, dy: int, score: float, res: float) -> Match:
    return Match(_pose(candidates, k, dx, dy, res), float(score), candidates.angle_step_rad, res)


class HeadingTable:
    """Every heading's best pose in a small window, each leaf scored once: the search a
    sighting pins (:meth:`SearchWindow.pinned`).

    A pinned window is a metre across but turns through every heading, and a merge asks
    it for the best pose and then, up to ten times, for the best pose away from those
    found. Where every exclusion zone spans the window in x and y (a merge's zones are
    1 m or 0.35 rad; the window 1 m), the best pose outside the zones is the best of the
    headings outside them, so one table of each heading's best answers every question.
    On an office floor's merge evidence (~750 points within 10 m, 628 headings) the
    table took 35-50 ms, where each branch and bound took 15-190 ms and a merge's
    twelve about a second: at 0.1 m cells the pyramid's coarse blocks (1.6 m) bound
    little. Scores equal :func:`exhaustive_match`'s; a tie goes to the lowest heading,
    then offset."""

    def __init__(
        self, points_m: np.ndarray, pyramid: LikelihoodPyramid, window: SearchWindow
    ) -> None:
        self._points_m = np.asarray(points_m, dtype=float).reshape(-1, 2)
        self._pyramid = pyramid
        self._window = window
        self._candidates = _candidates(self._points_m, pyramid.spec, window)
        self._scores, self._dx, self._dy = _best_per_angle(
            pyramid.levels[0], pyramid.pad, self._candidates.cells, *self._candidates.offsets
        )

    def best(
        self,
        min_score: float = 0.0,
        excluded: tuple[Match, ...] = (),
        excluded_radius_m: float = 0.0,
        excluded_angle_rad: float = 0.0,
    ) -> Match | None:
        """What :func:`best_match` returns for these arguments (by branch and bound where
        a zone leaves part of the window at its headings)."""
        candidates, res = self._candidates, self._pyramid.spec.resolution_m
        zones = _zones(candidates, list(excluded), excluded_radius_m, excluded_angle_rad, res)
        columns, rows = candidates.offsets
        spans = (
            (zones[:, 1] - zones[:, 4] <= 0)
            & (zones[:, 1] + zones[:, 4] >= columns - 1)
            & (zones[:, 2] - zones[:, 4] <= 0)
            & (zones[:, 2] + zones[:, 4] >= rows - 1)
        )
        if not spans.all():
            return best_match(
                self._points_m, self._pyramid, self._window, min_score, excluded,
                excluded_radius_m, excluded_angle_rad,
            )  # fmt: skip
        angles = len(candidates.angles_rad)
        k = np.arange(angles)
        allowed = self._scores > min_score
        for zone in zones:
            steps = np.abs(k - zone[0])
            if self._window.half_angle_rad >= math.pi:
                steps = np.minimum(steps, angles - steps)
            allowed &= steps > zone[3]
        if not allowed.any():
            return None
        best = int(np.flatnonzero(allowed)[np.argmax(self._scores[allowed])])
        return _match(
            candidates, best, int(self._dx[best]), int(self._dy[best]),
            float(self._scores[best]), res,
        )  # fmt: skip
