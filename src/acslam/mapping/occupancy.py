"""Log-odds occupancy grids built from posed LiDAR scans (thesis §4.4.3, eqs. 4.25-4.34).

SLAM corrects poses after their scans were integrated, so a scan must be removable at its
old pose and re-added at the new one. Clamping the log-odds (eq. 4.25 plus [min, max]
bounds) would make that removal inexact, so a grid keeps an *unclamped* accumulator and
derives the clamped log-odds from it when read. The accumulator is fixed point (int64 in
units of 2**-24 log-odds): each scan's update is rounded once, deterministically, and then
added or subtracted as integers. Integer addition is exact and order independent, so after
any sequence of corrections the grid is bit-identical to one built from scratch at the
final poses, and the global map is exactly the sum of the per-robot maps.

The price of the unclamped sum is that a cell seen occupied many times needs as many free
observations to flip: the grid assumes a static world, which is what the thesis maps.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable
from dataclasses import dataclass

import numba
import numpy as np

from acslam.config import MappingConfig
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, bresenham_start, bresenham_step

FIXED_POINT_SCALE = float(2**24)
"""Accumulator units per log-odds unit (a power of two, so conversion is exact)."""

_FREE_BIT, _HIT_BIT, _LISTED_BIT = 1, 2, 4

HIT_DEPTH_CELLS = 0.5
"""A return marks the cell this many cells *beyond* the measured range (ours, not in the
thesis). A return comes from the obstacle's surface, which is a cell boundary of the true
grid, so the measured endpoint falls in the free cell in front of the wall about half the
time even without noise; walls then grow a cell toward the robot (false positives on the
free side). Half a cell deeper puts noise-free hits in the wall's first cell and moves the
boundary case to one range-noise sigma of half a cell."""


def grid_spec_for_bounds(
    x_min_m: float, y_min_m: float, x_max_m: float, y_max_m: float, resolution_m: float
) -> GridSpec:
    """Smallest grid at ``resolution_m`` whose cells cover the rectangle of the bounds."""
    if not (x_max_m > x_min_m and y_max_m > y_min_m and resolution_m > 0):
        raise ValueError("bounds must have x_max > x_min, y_max > y_min and resolution > 0")
    cols = math.ceil((x_max_m - x_min_m) / resolution_m - 1e-9)
    rows = math.ceil((y_max_m - y_min_m) / resolution_m - 1e-9)
    return GridSpec(float(x_min_m), float(y_min_m), float(resolution_m), rows, cols)


def _logit(probability: float) -> float:
    if probability <= 0.0:
        return -math.inf
    if probability >= 1.0:
        return math.inf
    return math.log(probability / (1.0 - probability))


@dataclass(frozen=True)
class ScanUpdate:
    """Sparse change one posed scan makes: unique flat cell indices, in increasing order
    (adding them to a grid then reads it front to back), and fixed-point deltas.

    Computed once and applied to several grids (global and per-robot), which is why it is
    separate from :meth:`LogOddsGrid.apply`.
    """

    grid_shape: tuple[int, int]
    flat_indices: np.ndarray
    increments_fixed: np.ndarray

    def log_odds_increments(self) -> np.ndarray:
        """The increments in log-odds units (for inspection and tests)."""
        return self.increments_fixed / FIXED_POINT_SCALE


@numba.njit(cache=True, nogil=True)
def _scan_update(
    ranges: np.ndarray,
    angles: np.ndarray,
    x_m: float,
    y_m: float,
    theta_rad: float,
    origin_x_m: float,
    origin_y_m: float,
    resolution_m: float,
    state: np.ndarray,
    hit_weight: np.ndarray,
    range_max_m: float,
    free_on_no_return: bool,
    delta_free: float,
    delta_occ: float,
    alpha_per_m: float,
    kernel_rows: np.ndarray,
    kernel_cols: np.ndarray,
    kernel_weights: np.ndarray,
    hit_depth_m: float,
    hit_range_max_m: float,
    far_free_margin_m: float,
    kernel_beyond_hit: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Rasterise one scan; ``state``/``hit_weight`` are zeroed scratch grids, left zeroed."""
    rows, cols = state.shape
    n = ranges.shape[0]
    r0 = int(np.floor((y_m - origin_y_m) / resolution_m))
    c0 = int(np.floor((x_m - origin_x_m) / resolution_m))
    end_r = np.empty(n, np.int64)
    end_c = np.empty(n, np.int64)
    used = np.zeros(n, np.bool_)
    hit = np.zeros(n, np.bool_)
    count = 0  # cells marked
    # The block every marked cell lies in: the sensor's cell, the beams' ends and the
    # kernel around them (pass 4 sweeps it row by row).
    first_row, last_row, first_col, last_col = r0, r0, c0, c0
    # Pass 1: beam endpoints. Endpoint cells are marked first so that no beam of the same
    # scan clears them (a grazing neighbour beam must not erase a hit).
    for b in range(n):
        rng = ranges[b]
        if rng <= 0.0:  # invalid reading (messages.LidarScan): says nothing
            continue
        if rng <= hit_range_max_m:
            length = rng + hit_depth_m
            hit[b] = True
        elif rng <= range_max_m:
            length = max(0.0, rng - far_free_margin_m)
        elif np.isinf(rng) and not free_on_no_return:
            continue
        else:
            length = range_max_m
        used[b] = True
        a = theta_rad + angles[b]
        end_r[b] = int(np.floor((y_m + length * np.sin(a) - origin_y_m) / resolution_m))
        end_c[b] = int(np.floor((x_m + length * np.cos(a) - origin_x_m) / resolution_m))
        r, c = end_r[b], end_c[b]
        first_row, last_row = min(first_row, r), max(last_row, r)
        first_col, last_col = min(first_col, c), max(last_col, c)
        if hit[b] and 0 <= r < rows and 0 <= c < cols:
            count += state[r, c] == 0
            state[r, c] |= _HIT_BIT

    # Pass 2: free cells along each beam (eq. 4.33), endpoint excluded.
    for b in range(n):
        if not used[b]:
            continue
        steps, err, drow, dcol, step_r, step_c = bresenham_start(r0, c0, end_r[b], end_c[b])
        r, c = r0, c0
        for _ in range(steps):
            if 0 <= r < rows and 0 <= c < cols and (state[r, c] & _HIT_BIT) == 0:
                count += state[r, c] == 0
                state[r, c] |= _FREE_BIT
            r, c, err = bresenham_step(r, c, err, drow, dcol, step_r, step_c)

    # Pass 3: Gaussian kernel around each endpoint (eq. 4.34), max over the scan's beams
    # (without the cells beyond the endpoint unless kernel_beyond_hit, see LogOddsGrid).
    for b in np.nonzero(hit)[0]:
        ux = uy = 0.0
        if not kernel_beyond_hit:
            ux = np.cos(theta_rad + angles[b])
            uy = np.sin(theta_rad + angles[b])
        for k in range(kernel_rows.shape[0]):
            if not kernel_beyond_hit and kernel_cols[k] * ux + kernel_rows[k] * uy > 1e-9:
                continue  # behind the endpoint along the beam: the beam saw nothing there
            r = end_r[b] + kernel_rows[k]
            c = end_c[b] + kernel_cols[k]
            if 0 <= r < rows and 0 <= c < cols and kernel_weights[k] > hit_weight[r, c]:
                count += state[r, c] == 0
                state[r, c] |= _LISTED_BIT
                hit_weight[r, c] = kernel_weights[k]

    # Pass 4: distance-weighted increments, rounded once to fixed point; scratch reset.
    # Row by row over the block: the cells come out in grid order, which the grids they
    # are added to are read in.
    span = 0
    for k in range(kernel_rows.shape[0]):
        span = max(span, abs(kernel_rows[k]), abs(kernel_cols[k]))
    flat_out = np.empty(count, np.int64)
    delta_out = np.empty(count, np.int64)
    m = 0
    for r in range(max(first_row - span, 0), min(last_row + span + 1, rows)):
        for c in range(max(first_col - span, 0), min(last_col + span + 1, cols)):
            if state[r, c] == 0:
                continue
            # sqrt of the squares, not hypot: a third of the scan's time went to hypot's
            # overflow-safe scaling, needless at map distances.
            dx_m = origin_x_m + (c + 0.5) * resolution_m - x_m
            dy_m = origin_y_m + (r + 0.5) * resolution_m - y_m
            d = math.sqrt(dx_m * dx_m + dy_m * dy_m)
            falloff = max(0.0, 1.0 - alpha_per_m * d)
            delta = delta_occ * hit_weight[r, c] * falloff
            if (state[r, c] & _FREE_BIT) != 0:
                delta += delta_free * falloff
            fixed = np.int64(np.floor(delta * FIXED_POINT_SCALE + 0.5))
            state[r, c] = 0
            hit_weight[r, c] = 0.0
            if fixed != 0:
                flat_out[m] = r * cols + c
                delta_out[m] = fixed
                m += 1
    return flat_out[:m], delta_out[:m]


_NO_WINDOW = np.zeros((0, 0), dtype=np.int64)


@numba.njit(cache=True, nogil=True)
def _add_to_grids(
    flat_indices: np.ndarray,
    increments: np.ndarray,
    sign: int,
    global_acc: np.ndarray,
    robot_acc: np.ndarray,
    has_window: bool,
    window_acc: np.ndarray,
    window_first_row: int,
    window_first_col: int,
) -> tuple[int, int, int, int, bool]:
    """Add ``sign`` x ``increments`` at ``flat_indices`` (of the global grid's cells) to
    the global and the robot accumulator, and, if ``has_window``, to the window's
    accumulator, whose cell (0, 0) is the grid's (``window_first_row``,
    ``window_first_col``). One pass, no temporaries: a submap scan of 360 beams on a
    1,200 x 1,600 grid takes 0.62 ms, against 0.81 ms with the NumPy fancy-index adds
    (and the rows and columns they needed) that this replaces.

    Returns the block the cells span, ``(row_start, row_stop, col_start, col_stop)``
    (empty: all zero), and whether the window holds every cell (the window's accumulator
    is left alone if not; True without a window)."""
    cols = global_acc.shape[1]
    row_start, row_stop, col_start, col_stop = global_acc.shape[0], 0, cols, 0
    for i in range(flat_indices.shape[0]):
        r = flat_indices[i] // cols
        c = flat_indices[i] - r * cols
        delta = sign * increments[i]
        global_acc[r, c] += delta
        robot_acc[r, c] += delta
        row_start, row_stop = min(row_start, r), max(row_stop, r + 1)
        col_start, col_stop = min(col_start, c), max(col_stop, c + 1)
    if row_stop == 0:
        return 0, 0, 0, 0, True
    if not has_window:
        return row_start, row_stop, col_start, col_stop, True
    inside = (
        row_start >= window_first_row
        and col_start >= window_first_col
        and row_stop - window_first_row <= window_acc.shape[0]
        and col_stop - window_first_col <= window_acc.shape[1]
    )
    if inside:
        for i in range(flat_indices.shape[0]):
            r = flat_indices[i] // cols
            c = flat_indices[i] - r * cols
            window_acc[r - window_first_row, c - window_first_col] += sign * increments[i]
    return row_start, row_stop, col_start, col_stop, inside


@numba.njit(cache=True, nogil=True)
def _place_rigid(
    source: np.ndarray,
    source_origin_xy_m: tuple[float, float],
    transform: tuple[float, float, float, float],
    target: np.ndarray,
    target_origin_xy_m: tuple[float, float],
    resolution_m: float,
    sign: int,
) -> tuple[int, int, int, int]:
    """Add ``sign`` x ``source`` moved by the rigid ``transform`` = (cos, sin, tx, ty) into
    ``target``: every target cell whose centre maps back into the source takes the source
    cell it lands in (nearest-cell inverse mapping: no holes under rotation). Returns the
    target rows and columns it visited, ``(row_start, row_stop, col_start, col_stop)``."""
    cos_t, sin_t, tx_m, ty_m = transform
    sx_m, sy_m = source_origin_xy_m
    gx_m, gy_m = target_origin_xy_m
    rows, cols = source.shape
    x_lo = y_lo = math.inf
    x_hi = y_hi = -math.inf
    for corner in range(4):
        qx = sx_m + (corner & 1) * cols * resolution_m
        qy = sy_m + (corner >> 1) * rows * resolution_m
        px = cos_t * qx - sin_t * qy + tx_m
        py = sin_t * qx + cos_t * qy + ty_m
        x_lo, x_hi = min(x_lo, px), max(x_hi, px)
        y_lo, y_hi = min(y_lo, py), max(y_hi, py)
    c_start = max(0, math.floor((x_lo - gx_m) / resolution_m))
    c_stop = min(target.shape[1], math.floor((x_hi - gx_m) / resolution_m) + 1)
    r_start = max(0, math.floor((y_lo - gy_m) / resolution_m))
    r_stop = min(target.shape[0], math.floor((y_hi - gy_m) / resolution_m) + 1)
    for r in range(r_start, r_stop):
        dy = gy_m + (r + 0.5) * resolution_m - ty_m
        for c in range(c_start, c_stop):
            dx = gx_m + (c + 0.5) * resolution_m - tx_m
            sc = math.floor((cos_t * dx + sin_t * dy - sx_m) / resolution_m)
            sr = math.floor((cos_t * dy - sin_t * dx - sy_m) / resolution_m)
            if 0 <= sr < rows and 0 <= sc < cols and source[sr, sc] != 0:
                target[r, c] += sign * source[sr, sc]
    return r_start, r_stop, c_start, c_stop


class LogOddsGrid:
    """Occupancy grid in the world frame on a fixed :class:`GridSpec` (eqs. 4.25-4.26).

    Per scan, each cell gets at most one update: an endpoint cell of any beam gets the
    occupied update only; a cell crossed by a beam gets one free update (4.33) plus, if it
    lies within ``hit_radius_m`` of an endpoint, the largest Gaussian occupied update
    (4.34) of the scan's endpoints. Both are weighted by ``max(0, 1 - alpha d)`` with d the
    distance from the sensor to the cell centre. Counting each cell once per scan keeps the
    many overlapping beams near the sensor from dominating the map.

    Two options depart from eq. 4.34 for worlds of thin structures, whose far side no
    beam ever clears (a vineyard's 10 cm fence: mapped at the true poses, 4900 of the
    map's 6700 false occupied cells lay behind it):

    - ``kernel_beyond_hit`` False: the kernel skips cells beyond the endpoint along the
      beam, which says nothing about what lies behind the surface it hit; the kernel's
      share there grew every thin wall by a cell on its far side.
    - ``hit_max_range_m`` below ``max_range_m``: longer returns clear free space up to
      ``far_free_margin_m`` short of the return but mark nothing occupied. The LDS-02's
      range sigma passes a cell at 3 m and is 2.5 cells at 8 m; far returns smeared the
      fence 2-4 cells deep. Nearer views map those surfaces instead.

    Both leave far or grazing walls with gaps until a robot comes near, and gaps next to
    free space are frontiers: together they doubled exploration times in the thesis
    worlds (thesis-exp2, 3 robots: 76 s against 32-36 s with either alone) and left the
    vineyard scenario 700 frontier cells that never closed, so they are off by default:
    options for mapping thin structures, not for exploring them.
    """

    def __init__(
        self, spec: GridSpec, config: MappingConfig, accumulator: np.ndarray | None = None
    ) -> None:
        self.spec = spec
        self.config = config
        if accumulator is None:
            accumulator = np.zeros(spec.shape, dtype=np.int64)
        elif accumulator.shape != spec.shape or accumulator.dtype != np.int64:
            raise ValueError(f"accumulator must be int64 of shape {spec.shape}")
        self._accumulator = accumulator
        self._scratch: tuple[np.ndarray, np.ndarray] | None = None
        reach_cells = config.hit_radius_m / spec.resolution_m
        span = math.floor(reach_cells + 1e-9)
        dr, dc = np.mgrid[-span : span + 1, -span : span + 1]
        inside = (dr**2 + dc**2) <= reach_cells**2 + 1e-9
        self._kernel_rows = dr[inside].astype(np.int64)
        self._kernel_cols = dc[inside].astype(np.int64)
        sq_dist_m2 = (dr[inside] ** 2 + dc[inside] ** 2) * spec.resolution_m**2
        self._kernel_weights = np.exp(-sq_dist_m2 / (2.0 * config.hit_sigma_m**2))
        self._occupied_log_odds = _logit(config.occupied_probability)
        self._free_log_odds = _logit(config.free_probability)

    @classmethod
    def for_bounds(
        cls,
        x_min_m: float,
        y_min_m: float,
        x_max_m: float,
        y_max_m: float,
        config: MappingConfig,
    ) -> LogOddsGrid:
        """Empty grid covering the given world rectangle at ``config.resolution_m``."""
        spec = grid_spec_for_bounds(x_min_m, y_min_m, x_max_m, y_max_m, config.resolution_m)
        return cls(spec, config)

    @property
    def accumulator_fixed(self) -> np.ndarray:
        """Unclamped log-odds sum in fixed-point units (read-only view)."""
        view = self._accumulator.view()
        view.flags.writeable = False
        return view

    def scan_update(
        self,
        scan_ranges: np.ndarray,
        scan_angles: np.ndarray,
        sensor_pose_xytheta: np.ndarray,
        range_max_m: float = math.inf,
    ) -> ScanUpdate:
        """Change one scan makes; a pure function of its arguments (needed for removal).

        ``ranges`` in metres with ``inf`` = no return, ``angles`` in the sensor frame,
        ``sensor_pose_xytheta`` in the world frame. Beams are used up to
        ``min(range_max_m, config.max_range_m)``; longer ones only clear free space.
        """
        ranges = np.ascontiguousarray(scan_ranges, dtype=np.float64)
        angles = np.ascontiguousarray(scan_angles, dtype=np.float64)
        if ranges.ndim != 1 or ranges.shape != angles.shape:
            raise ValueError("scan_ranges and scan_angles must be (N,) of equal length")
        if np.isnan(ranges).any() or (ranges < 0).any():
            raise ValueError("scan_ranges must be >= 0 or +inf (no return), never NaN")
        x_m, y_m, theta_rad = (float(v) for v in np.asarray(sensor_pose_xytheta).reshape(3))
        if self._scratch is None:
            self._scratch = (
                np.zeros(self.spec.shape, dtype=np.uint8),
                np.zeros(self.spec.shape, dtype=np.float64),
            )
        cfg = self.config
        flat, increments = _scan_update(
            ranges,
            angles,
            x_m,
            y_m,
            theta_rad,
            self.spec.origin_x_m,
            self.spec.origin_y_m,
            self.spec.resolution_m,
            self._scratch[0],
            self._scratch[1],
            min(float(range_max_m), cfg.max_range_m),
            cfg.free_on_no_return,
            cfg.delta_free,
            cfg.delta_occ,
            cfg.distance_alpha_per_m,
            self._kernel_rows,
            self._kernel_cols,
            self._kernel_weights,
            HIT_DEPTH_CELLS * self.spec.resolution_m,
            min(float(range_max_m), cfg.max_range_m, cfg.hit_max_range_m or math.inf),
            cfg.far_free_margin_m,
            cfg.kernel_beyond_hit,
        )
        return ScanUpdate(self.spec.shape, flat, increments)

    def apply(self, update: ScanUpdate, sign: int = 1) -> None:
        """Add (``sign=+1``) or exactly remove (``sign=-1``) a scan update."""
        if sign not in (1, -1):
            raise ValueError(f"sign must be +1 or -1, got {sign!r}")
        if update.grid_shape != self.spec.shape:
            raise ValueError("scan update was computed for a grid of another shape")
        self._accumulator.reshape(-1)[update.flat_indices] += sign * update.increments_fixed

    def place(
        self,
        source_fixed: np.ndarray,
        source_origin_xy_m: tuple[float, float],
        transform: tuple[float, float, float, float],
        sign: int,
    ) -> tuple[int, int, int, int]:
        """Add (``sign=+1``) or exactly remove (``-1``) another accumulator at this grid's
        resolution, moved by the rigid ``transform`` (cos, sin, tx, ty). The identity
        copies it cell for cell when both grids' cells are aligned. Returns the rows and
        columns it may have changed, ``(row_start, row_stop, col_start, col_stop)``."""
        if sign not in (1, -1):
            raise ValueError(f"sign must be +1 or -1, got {sign!r}")
        spec = self.spec
        return _place_rigid(
            source_fixed,
            source_origin_xy_m,
            transform,
            self._accumulator,
            (spec.origin_x_m, spec.origin_y_m),
            spec.resolution_m,
            sign,
        )

    def integrate(
        self,
        scan_ranges: np.ndarray,
        scan_angles: np.ndarray,
        sensor_pose_xytheta: np.ndarray,
        sign: int = 1,
        range_max_m: float = math.inf,
    ) -> None:
        """Integrate one posed scan (``sign=-1`` removes it exactly)."""
        self.apply(
            self.scan_update(scan_ranges, scan_angles, sensor_pose_xytheta, range_max_m), sign
        )

    def log_odds(self, rows: slice = slice(None), cols: slice = slice(None)) -> np.ndarray:
        """Clamped log-odds L of every cell (float64), or of the block ``rows, cols``."""
        return np.clip(
            self._accumulator[rows, cols] * (1.0 / FIXED_POINT_SCALE),
            self.config.log_odds_min,
            self.config.log_odds_max,
        )

    def probabilities(self) -> np.ndarray:
        """Occupancy probability 1 / (1 + exp(-L)) of every cell (eq. 4.26)."""
        return 1.0 / (1.0 + np.exp(-self.log_odds()))

    def to_occupancy_values(
        self, rows: slice = slice(None), cols: slice = slice(None)
    ) -> np.ndarray:
        """int8 OccupancyGrid values: 100 if p >= occupied_probability, 0 if p <=
        free_probability, -1 otherwise (compared in log-odds, the same test); of every
        cell, or of the block ``rows, cols``."""
        log_odds = self.log_odds(rows, cols)
        values = np.full(log_odds.shape, UNKNOWN, dtype=np.int8)
        values[log_odds <= self._free_log_odds] = FREE
        values[log_odds >= self._occupied_log_odds] = OCCUPIED
        return values

    def known_mask(self) -> np.ndarray:
        """Cells classified free or occupied (the coverage of the map)."""
        log_odds = self.log_odds()
        return (log_odds <= self._free_log_odds) | (log_odds >= self._occupied_log_odds)


@dataclass(frozen=True)
class _PosedScan:
    robot_id: int
    ranges: np.ndarray
    angles: np.ndarray
    pose: np.ndarray
    range_max_m: float


class FusedGrids:
    """The global map fused from all robots plus one map per robot, kept in step.

    Because accumulators are exact integers, the global grid always equals the sum of the
    robot grids, so the map of any robot combination is available (:meth:`combined`).
    Mappers differ in how scans reach these grids (:class:`TeamMap`, and the submaps of
    :mod:`acslam.mapping.submaps`).
    """

    def __init__(self, config: MappingConfig, *, spec: GridSpec) -> None:
        self.spec = spec
        self.config = config
        self.global_grid = LogOddsGrid(spec, config)
        self._robot_grids: dict[int, LogOddsGrid] = {}
        self._version = 0
        self._values: tuple[int, np.ndarray] | None = None
        self._changed: tuple[int, int, int, int] | None = None
        """Rows and columns of the global grid changed since ``_values`` was computed,
        ``(row_start, row_stop, col_start, col_stop)``; None: none."""

    @property
    def version(self) -> int:
        """Counts changes to the map: readers compare it to skip unchanged maps."""
        return self._version

    def occupancy_values(self) -> np.ndarray:
        """The global grid as read-only OccupancyGrid values, computed once per version.

        Only the block the changes since the last call touched is classified again, so
        a map update costs the area that changed (and a copy), not the whole grid.
        """
        if self._values is None:
            values = self.global_grid.to_occupancy_values()
        elif self._values[0] != self._version:
            values = self._values[1].copy()
            if self._changed is not None:
                r0, r1, c0, c1 = self._changed
                rows, cols = slice(r0, r1), slice(c0, c1)
                values[rows, cols] = self.global_grid.to_occupancy_values(rows, cols)
        else:
            return self._values[1]
        values.flags.writeable = False
        self._values, self._changed = (self._version, values), None
        return values

    def _mark_changed(self, row_start: int, row_stop: int, col_start: int, col_stop: int) -> None:
        """Widen the block of changed global cells (see ``occupancy_values``)."""
        if row_start >= row_stop or col_start >= col_stop:
            return
        if self._changed is not None:
            r0, r1, c0, c1 = self._changed
            row_start, row_stop = min(row_start, r0), max(row_stop, r1)
            col_start, col_stop = min(col_start, c0), max(col_stop, c1)
        self._changed = (row_start, row_stop, col_start, col_stop)

    def known_mask(self) -> np.ndarray:
        """The global grid's known cells, read off :meth:`occupancy_values`: it is
        classified again only where the map changed, where classifying the whole grid
        cost 80 ms a call on a frame's grid of 5 M cells (unknown starts)."""
        return self.occupancy_values() != UNKNOWN

    def robot_known_mask(self, robot_id: int) -> np.ndarray:
        return self.robot_grid(robot_id).known_mask()

    @property
    def robot_ids(self) -> list[int]:
        return sorted(self._robot_grids)

    def robot_grid(self, robot_id: int) -> LogOddsGrid:
        """The map built from this robot's scans only (empty if it has none yet)."""
        if robot_id not in self._robot_grids:
            self._robot_grids[robot_id] = LogOddsGrid(self.spec, self.config)
        return self._robot_grids[robot_id]

    def combined(self, robot_ids: Iterable[int]) -> LogOddsGrid:
        """Map fused from the scans of the given robots only (a new, independent grid)."""
        total = np.zeros(self.spec.shape, dtype=np.int64)
        for robot_id in robot_ids:
            if robot_id in self._robot_grids:
                total += self._robot_grids[robot_id].accumulator_fixed
        return LogOddsGrid(self.spec, self.config, total)

    def _apply(
        self,
        robot_id: int,
        update: ScanUpdate,
        sign: int,
        window: tuple[np.ndarray, int, int] | None = None,
    ) -> bool:
        """Add or remove one scan update in the global grid and the robot's grid, and in
        ``window`` (an accumulator and the grid row and column of its first cell) if
        given. Returns whether the window holds every changed cell (if not, the window
        is left alone; True without a window)."""
        if update.grid_shape != self.spec.shape:
            raise ValueError("scan update was computed for a grid of another shape")
        window_acc, first_row, first_col = (_NO_WINDOW, 0, 0) if window is None else window
        *block, inside = _add_to_grids(
            update.flat_indices,
            update.increments_fixed,
            sign,
            self.global_grid._accumulator,
            self.robot_grid(robot_id)._accumulator,
            window is not None,
            window_acc,
            first_row,
            first_col,
        )
        self._mark_changed(*block)
        self._version += 1
        return inside


class TeamMap(FusedGrids):
    """Exact re-integration: every scan is stored by key with its current pose, and
    :meth:`move_scan` removes it at the old pose and re-adds it at the new one. A
    correction costs a ray cast per beam of every scan that moved."""

    history_free = True  # exact integer sums: any order of adds and moves, the same grid

    def __init__(self, config: MappingConfig, *, spec: GridSpec) -> None:
        super().__init__(config, spec=spec)
        self._scans: dict[Hashable, _PosedScan] = {}

    def __len__(self) -> int:
        return len(self._scans)

    def __contains__(self, scan_key: Hashable) -> bool:
        return scan_key in self._scans

    def scan_pose(self, scan_key: Hashable) -> np.ndarray:
        """Current sensor pose ``[x, y, theta]`` of a stored scan."""
        return self._scans[scan_key].pose.copy()

    def _apply_scan(self, scan: _PosedScan, pose: np.ndarray, sign: int) -> None:
        update = self.global_grid.scan_update(scan.ranges, scan.angles, pose, scan.range_max_m)
        self._apply(scan.robot_id, update, sign)

    def add_scan(
        self,
        robot_id: int,
        scan_key: Hashable,
        ranges: np.ndarray,
        angles: np.ndarray,
        pose: np.ndarray,
        range_max_m: float = math.inf,
    ) -> None:
        """Integrate a scan taken at sensor ``pose`` and remember it under ``scan_key``."""
        if scan_key in self._scans:
            raise KeyError(f"scan {scan_key!r} was already added")
        scan = _PosedScan(
            int(robot_id),
            np.asarray(ranges, dtype=np.float64),  # shared, not copied: messages are read-only
            np.asarray(angles, dtype=np.float64),
            np.array(pose, dtype=np.float64).reshape(3),
            float(range_max_m),
        )
        self._apply_scan(scan, scan.pose, 1)
        self._scans[scan_key] = scan

    def move_scan(self, scan_key: Hashable, new_pose: np.ndarray) -> None:
        """Re-place a scan after a pose correction: exact removal at the old pose, then add."""
        scan = self._scans[scan_key]
        pose = np.array(new_pose, dtype=np.float64).reshape(3)
        if np.array_equal(pose, scan.pose):
            return
        self._apply_scan(scan, scan.pose, -1)
        moved = _PosedScan(scan.robot_id, scan.ranges, scan.angles, pose, scan.range_max_m)
        self._apply_scan(moved, pose, 1)
        self._scans[scan_key] = moved

    def remove_scan(self, scan_key: Hashable) -> None:
        """Take a scan out of every grid it is in."""
        scan = self._scans.pop(scan_key)
        self._apply_scan(scan, scan.pose, -1)
