"""Frontier detection on the shared occupancy grid (thesis §4.5).

A *frontier cell* is a free cell with at least one unknown cell among its in-grid
8-neighbours. Exploration only cares about frontiers a robot can reach, so the detector's
output is the set of frontier cells in the 8-connected free components that contain a
robot's (free) cell. :func:`reachable_frontier_cells` computes that set from scratch with
vectorised numpy/scipy (the reference oracle); :class:`EwfdFrontierDetector` maintains it
incrementally (Expanding Wavefront Frontier Detection).

EWFD state (shared by all robots, the thesis's "shared frontier grid"):

- ``known``: the detector's copy of the map values; the difference with the new map gives
  the cells whose state changed since the last update. Scans only change cells within
  the LiDAR range of their pose, so only each robot's *active area* (the bounding square
  of the disc of radius ``active_radius_m`` around the scan poses) is compared.
- ``visited``: the global memory of visited cells, i.e. the free cells reachable from the
  robots. Invariant after each update: ``visited`` is exactly the union of the free
  8-connected components of ``known`` that contain a robot cell.
- ``label``: a component id per visited cell (union-find over ids), so splits and merges
  are decided per component without a global pass.
- the frontier set, as an index list with a position grid (O(1) insert and removal).

An update, for the changed cells of all active areas (thesis §4.5, with the corrections
exactness needs; see the comments in :func:`_process`):

1. visited cells that stopped being free are removed; where a removed cell's visited
   neighbours are not connected around it, the pieces of its component are re-examined
   by a multi-source BFS from those neighbours that stops as soon as all pieces met or
   all but one are exhausted (real splits);
2. the wavefront expands from the previous wavefront: newly free cells next to visited
   cells (that is, next to previous frontier cells when they were unknown) seed a BFS
   that passes through newly explored free cells *and* through free cells that were free
   but unreachable before: a newly free cell (e.g. a door cell seen free) can connect a
   region explored earlier from elsewhere, and the thesis's "only new cells" rule would
   miss it. That region is visited once, then remembered. Robot cells that are free but
   unvisited start their own wavefront (the first update's BFS from the robot cell);
3. components that no longer contain a robot are forgotten;
4. the frontier status is recomputed only for cells whose visited state changed and for
   the changed cells and their 8-neighbours; frontier cells whose unknown neighbours got
   explored are removed there.

Multi-robot merging (thesis: "prioritizing newly confirmed frontiers when cells were
previously globally marked as unknown, and identifying as free those cells visited by at
least one robot"): the robots' active areas are read into one fused map and every
expansion writes into the shared grids, so a cell is visited as soon as one robot's
wavefront reaches it (union of the visited sets), and a cell's frontier status is
recomputed from the fused map whenever any robot's data touches it or its neighbours:
the latest information wins, the result does not depend on the order of the robots, and
a frontier confirmed by one robot is dropped as soon as another robot's data explores
its last unknown neighbour.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from scipy import ndimage

from acslam.config import MappingConfig
from acslam.exploration.params import EwfdParams, NaiveFrontierParams
from acslam.grid import FREE, NEIGHBOUR_COLS, NEIGHBOUR_ROWS, UNKNOWN, GridSpec, neighbour_flat

_EIGHT = np.ones((3, 3), dtype=bool)


# --------------------------------------------------------------------------- oracle


def frontier_mask(values: np.ndarray) -> np.ndarray:
    """Naive full-grid detector: free cells with an unknown in-grid 8-neighbour."""
    values = np.asarray(values)
    unknown = values == UNKNOWN
    near_unknown = ndimage.binary_dilation(unknown, structure=_EIGHT)
    return near_unknown & (values == FREE)


def reachable_free_mask(values: np.ndarray, robot_cells: np.ndarray) -> np.ndarray:
    """Free cells 8-connected through free space to a robot cell that is itself free."""
    free = np.asarray(values) == FREE
    labels, _ = ndimage.label(free, structure=_EIGHT)
    cells = np.asarray(robot_cells, dtype=np.int64).reshape(-1, 2)
    rows, cols = free.shape
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < rows) & (cells[:, 1] >= 0) & (cells[:, 1] < cols)
    seeds = labels[cells[inside, 0], cells[inside, 1]]
    seeds = seeds[seeds > 0]
    return np.isin(labels, seeds) if len(seeds) else np.zeros_like(free)


def reachable_frontier_cells(values: np.ndarray, robot_cells: np.ndarray) -> np.ndarray:
    """Reference result: (F, 2) ``[row, col]`` frontier cells reachable from the robots,
    in row-major order."""
    mask = frontier_mask(values) & reachable_free_mask(values, robot_cells)
    return np.argwhere(mask)


def away_from_robots(
    frontier_cells: np.ndarray, robot_cells: np.ndarray, spec: GridSpec, radius_m: float
) -> np.ndarray:
    """The frontier cells whose centres lie farther than ``radius_m`` from every robot's
    cell centre.

    A robot's LiDAR sees neither the cells under it nor those inside its minimum range, so
    until it moves it stands in a small unknown disc whose rim is a frontier: a cluster at
    its feet, which it reaches at once, and the allocation runs again and again (12 times
    in the first 4 simulated seconds of thesis-exp1 with seed 3; 3 times without those
    clusters). Those cells are left out of the clusters; the map keeps them unknown until
    a scan sees them.
    """
    cells = np.asarray(frontier_cells, dtype=np.int64).reshape(-1, 2)
    robots = np.asarray(robot_cells, dtype=np.int64).reshape(-1, 2)
    keep = np.ones(len(cells), dtype=bool)
    span = math.floor(radius_m / spec.resolution_m)
    for row, col in robots:
        # Only the cells in the robot's bounding square can lie within the radius.
        near = np.flatnonzero(
            (np.abs(cells[:, 0] - row) <= span) & (np.abs(cells[:, 1] - col) <= span)
        )
        gap_m = spec.resolution_m * np.hypot(cells[near, 0] - row, cells[near, 1] - col)
        keep[near[gap_m <= radius_m]] = False
    return cells[keep]


def active_radius_m(mapping: MappingConfig) -> float:
    """Radius around a scan pose beyond which the scan changes no cell.

    The beams are used up to ``max_range_m`` and the Gaussian hit kernel reaches
    ``hit_radius_m`` beyond an endpoint (thesis: active area radius = sensor range).
    """
    return mapping.max_range_m + mapping.hit_radius_m


# --------------------------------------------------------------------------- numba kernels


@numba.njit(cache=True, nogil=True)
def _find(parent: np.ndarray, a: int) -> int:
    root = a
    while parent[root] != root:
        root = parent[root]
    while parent[a] != root:
        nxt = parent[a]
        parent[a] = root
        a = nxt
    return root


class EwfdArrays(NamedTuple):
    """The detector's state, one value for the kernels (see the module docstring).

    ``known`` is (rows, cols) int8; ``visited`` and ``dirty_flag`` are flat uint8; the rest
    are flat int64. ``counters`` = [next component id, frontier count]; ``parent`` and
    ``piece_active`` are indexed by component id and grow with :meth:`_reserve_ids`.
    ``changed`` receives the flat cells :func:`_diff` finds; ``queue``, ``mark``,
    ``dirty`` and ``dirty_flag`` are scratch (``mark``, ``dirty_flag`` and
    ``piece_active`` are all zero between updates).
    """

    known: np.ndarray
    visited: np.ndarray
    label: np.ndarray
    parent: np.ndarray
    piece_active: np.ndarray
    counters: np.ndarray
    changed: np.ndarray
    queue: np.ndarray
    mark: np.ndarray
    dirty: np.ndarray
    dirty_flag: np.ndarray
    frontier_pos: np.ndarray
    frontier_list: np.ndarray


@numba.njit(cache=True, nogil=True)
def _diff(
    values: np.ndarray,
    values_words: np.ndarray,
    known_words: np.ndarray,
    windows: np.ndarray,
    ewfd: EwfdArrays,
) -> tuple[int, int]:
    """Copy the changed cells of the windows ``[r0, r1, c0, c1)`` into ``ewfd.known``.

    Returns how many changed cells were written to ``ewfd.changed`` (flat indices) and how many
    of them were visited (bounds the ids the update can create). Overlapping windows are
    compared once: the second sees no difference. ``*_words`` are uint64 views of the rows
    (8 cells a word, when the column count allows; else empty): mostly equal words are
    skipped 8 cells at a time, and a word's extra cells outside the window are real cells,
    so recording their changes too is harmless.
    """
    known, visited, changed = ewfd.known, ewfd.visited, ewfd.changed
    cols = known.shape[1]
    count = 0
    visited_count = 0
    use_words = values_words.shape[0] > 0
    for w in range(windows.shape[0]):
        c_start = windows[w, 2]
        c_stop = windows[w, 3]
        step = 1
        if use_words:
            c_start = (c_start // 8) * 8
            c_stop = min(((c_stop + 7) // 8) * 8, cols)
            step = 8
        for r in range(windows[w, 0], windows[w, 1]):
            for c0 in range(c_start, c_stop, step):
                if use_words and values_words[r, c0 // 8] == known_words[r, c0 // 8]:
                    continue
                for c in range(c0, c0 + step):
                    if values[r, c] != known[r, c]:
                        known[r, c] = values[r, c]
                        flat = r * cols + c
                        changed[count] = flat
                        count += 1
                        if visited[flat]:
                            visited_count += 1
    return count, visited_count


@numba.njit(cache=True, nogil=True)
def _ring_groups(
    visited: np.ndarray, row: int, col: int, rows: int, cols: int, firsts: np.ndarray
) -> int:
    """The groups of the visited 8-neighbours of (row, col) that are 8-connected among
    themselves, inside the ring; writes one cell of each group to ``firsts`` and returns
    how many there are.

    A removed cell whose visited neighbours form one group, and none of whose neighbours
    was removed too, cannot split its component: any path through it detours through
    the ring, whose cells stay visited. (Two removed cells side by side can close a
    passage that neither closes alone.)
    """
    group = np.full(8, -1, np.int64)
    n_groups = 0
    for k in range(8):
        v = neighbour_flat(row, col, k, rows, cols)
        if v < 0 or not visited[v]:
            continue
        own = -1
        for j in range(k):
            if group[j] < 0:
                continue
            if abs(NEIGHBOUR_ROWS[k] - NEIGHBOUR_ROWS[j]) > 1:
                continue
            if abs(NEIGHBOUR_COLS[k] - NEIGHBOUR_COLS[j]) > 1:
                continue
            if own < 0:
                own = group[j]
            elif group[j] != own:
                # k joins two groups: relabel the other one as ``own``.
                other = group[j]
                for m in range(k):
                    if group[m] == other:
                        group[m] = own
                n_groups -= 1
        if own < 0:
            own = k
            n_groups += 1
        group[k] = own
    count = 0
    for k in range(8):
        if group[k] == k:
            firsts[count] = neighbour_flat(row, col, k, rows, cols)
            count += 1
    return count


@numba.njit(cache=True, nogil=True)
def _next_to_removed(mark: np.ndarray, row: int, col: int, rows: int, cols: int) -> bool:
    """Whether an 8-neighbour of (row, col) is marked removed (-1) in ``mark``."""
    for k in range(8):
        v = neighbour_flat(row, col, k, rows, cols)
        if v >= 0 and mark[v] == -1:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _mark_dirty(flat: int, dirty: np.ndarray, dirty_flag: np.ndarray, n_dirty: int) -> int:
    if dirty_flag[flat] == 0:
        dirty_flag[flat] = 1
        dirty[n_dirty] = flat
        n_dirty += 1
    return n_dirty


@numba.njit(cache=True, nogil=True)
def _process(
    ewfd: EwfdArrays, n_changed: int, robots: np.ndarray, previous_robots: np.ndarray
) -> None:
    """Apply the first ``n_changed`` cells of ``ewfd.changed`` (already copied into
    ``ewfd.known``) to the EWFD state.

    ``robots``/``previous_robots`` are flat robot cells (-1: outside the grid).
    """
    rows, cols = ewfd.known.shape
    known = ewfd.known.reshape(-1)
    visited, label, parent = ewfd.visited, ewfd.label, ewfd.parent
    piece_active, state = ewfd.piece_active, ewfd.counters
    changed = ewfd.changed[:n_changed]
    queue, mark = ewfd.queue, ewfd.mark
    dirty, dirty_flag = ewfd.dirty, ewfd.dirty_flag
    frontier_pos, frontier_list = ewfd.frontier_pos, ewfd.frontier_list
    n_dirty = 0

    # 1. Visited cells that are no longer free leave the visited set. Every changed cell
    # and its neighbours need their frontier status recomputed (step 4).
    removed = np.empty(changed.shape[0], np.int64)
    n_removed = 0
    for i in range(changed.shape[0]):
        flat = changed[i]
        n_dirty = _mark_dirty(flat, dirty, dirty_flag, n_dirty)
        row, col = divmod(flat, cols)
        for k in range(8):
            v = neighbour_flat(row, col, k, rows, cols)
            if v >= 0:
                n_dirty = _mark_dirty(v, dirty, dirty_flag, n_dirty)
        if visited[flat] and known[flat] != FREE:
            visited[flat] = 0
            removed[n_removed] = flat
            n_removed += 1

    # 2. Split detection. The visited neighbours of the removed cells are the seeds of
    # "pieces" (local ids, local union-find ``lp``) that grow in one FIFO queue, i.e. in
    # lock step. Pieces that touch merge; a piece whose queue empties is a whole
    # component and, if other pieces of its original component are still growing, it
    # split off and gets a new component id. A component stops growing once a single
    # piece of it is left: that piece keeps the original id. Cost: a few cells when the
    # pieces touch around the removed cell; when they only meet through a detour (a cell
    # of a thin wall seen free by a noisy beam, then occupied again) it is the area both
    # sides cover until they meet. Pieces of one component stop only once all of them
    # met, so two removals far apart would grow until they meet across the component.
    # Hence only the removals that can split seed pieces, one per group of visited
    # neighbours: those whose neighbours fall into several groups within their ring, or
    # that lie next to another removed cell (:func:`_ring_groups`; removed cells are
    # marked -1 meanwhile). The others keep one neighbour as a candidate of step 4 (the
    # robot's own cell may be the one removed).
    max_pieces = 8 * n_removed + 1
    lp = np.empty(max_pieces, np.int64)
    pending = np.zeros(max_pieces, np.int64)
    origin = np.empty(max_pieces, np.int64)
    split_id = np.zeros(max_pieces, np.int64)
    seed_cells = np.empty(max_pieces, np.int64)
    unsplit_cells = np.empty(n_removed, np.int64)
    n_unsplit = 0
    firsts = np.empty(8, np.int64)
    n_pieces = 0
    tail = 0
    for i in range(n_removed):
        mark[removed[i]] = -1
    for i in range(n_removed):
        row, col = divmod(removed[i], cols)
        n_groups = _ring_groups(visited, row, col, rows, cols, firsts)
        if n_groups == 1 and not _next_to_removed(mark, row, col, rows, cols):
            unsplit_cells[n_unsplit] = firsts[0]
            n_unsplit += 1
            continue
        for g in range(n_groups):
            v = firsts[g]
            if mark[v] == 0:
                n_pieces += 1
                lp[n_pieces] = n_pieces
                pending[n_pieces] = 1
                root = _find(parent, label[v])
                origin[n_pieces] = root
                piece_active[root] += 1
                seed_cells[n_pieces] = v
                mark[v] = n_pieces
                queue[tail] = v
                tail += 1
    head = 0
    while head < tail:
        u = queue[head]
        head += 1
        p = _find(lp, mark[u])
        o = origin[p]
        pending[p] -= 1
        if piece_active[o] <= 1:
            continue
        row, col = divmod(u, cols)
        for k in range(8):
            v = neighbour_flat(row, col, k, rows, cols)
            if v < 0 or not visited[v]:
                continue
            m = mark[v]
            if m == 0:
                mark[v] = p
                queue[tail] = v
                tail += 1
                pending[p] += 1
            else:
                q = _find(lp, m)
                if q != p:
                    lp[q] = p
                    pending[p] += pending[q]
                    piece_active[o] -= 1
                    if piece_active[o] <= 1:
                        break
        if pending[p] == 0 and piece_active[o] > 1:
            new_id = state[0]
            state[0] += 1
            parent[new_id] = new_id
            split_id[p] = new_id
            piece_active[o] -= 1
    for i in range(tail):
        v = queue[i]
        p = _find(lp, mark[v])
        if split_id[p] != 0:
            label[v] = split_id[p]
        mark[v] = 0
    for p in range(1, n_pieces + 1):
        piece_active[origin[p]] = 0
    for i in range(n_removed):
        mark[removed[i]] = 0

    # 3. Wavefront expansion from the previous wavefront and from unvisited robot cells,
    # through every free unvisited cell (new or previously unreachable).
    tail = 0
    for i in range(changed.shape[0]):
        flat = changed[i]
        if known[flat] != FREE or visited[flat]:
            continue
        row, col = divmod(flat, cols)
        for k in range(8):
            v = neighbour_flat(row, col, k, rows, cols)
            if v >= 0 and visited[v]:
                visited[flat] = 1
                label[flat] = _find(parent, label[v])
                queue[tail] = flat
                tail += 1
                n_dirty = _mark_dirty(flat, dirty, dirty_flag, n_dirty)
                break
    for i in range(robots.shape[0]):
        flat = robots[i]
        if flat >= 0 and known[flat] == FREE and not visited[flat]:
            new_id = state[0]
            state[0] += 1
            parent[new_id] = new_id
            visited[flat] = 1
            label[flat] = new_id
            queue[tail] = flat
            tail += 1
            n_dirty = _mark_dirty(flat, dirty, dirty_flag, n_dirty)
    head = 0
    while head < tail:
        u = queue[head]
        head += 1
        lu = _find(parent, label[u])
        row, col = divmod(u, cols)
        for k in range(8):
            v = neighbour_flat(row, col, k, rows, cols)
            if v < 0 or known[v] != FREE:
                continue
            if not visited[v]:
                visited[v] = 1
                label[v] = lu
                queue[tail] = v
                tail += 1
                n_dirty = _mark_dirty(v, dirty, dirty_flag, n_dirty)
            else:
                lv = _find(parent, label[v])
                if lv != lu:
                    parent[lv] = lu

    # 4. Forget components without a robot. Every component now holds a previous robot
    # cell, a split seed, a neighbour of a removed cell or a new robot cell, so those are
    # the only candidates.
    kept = np.empty(robots.shape[0], np.int64)
    n_kept = 0
    for i in range(robots.shape[0]):
        flat = robots[i]
        if flat >= 0 and visited[flat]:
            kept[n_kept] = _find(parent, label[flat])
            n_kept += 1
    n_candidates = n_pieces + previous_robots.shape[0] + n_unsplit
    for i in range(n_candidates):
        if i < n_pieces:
            flat = seed_cells[i + 1]
        elif i < n_pieces + previous_robots.shape[0]:
            flat = previous_robots[i - n_pieces]
        else:
            flat = unsplit_cells[i - n_pieces - previous_robots.shape[0]]
        if flat < 0 or not visited[flat]:
            continue
        root = _find(parent, label[flat])
        is_kept = False
        for j in range(n_kept):
            if kept[j] == root:
                is_kept = True
        if is_kept:
            continue
        visited[flat] = 0
        queue[0] = flat
        head = 0
        tail = 1
        while head < tail:
            u = queue[head]
            head += 1
            n_dirty = _mark_dirty(u, dirty, dirty_flag, n_dirty)
            row, col = divmod(u, cols)
            for k in range(8):
                v = neighbour_flat(row, col, k, rows, cols)
                if v >= 0 and visited[v]:
                    visited[v] = 0
                    queue[tail] = v
                    tail += 1

    # 5. Frontier status of the cells whose visited state or neighbourhood changed.
    n_frontier = state[1]
    for i in range(n_dirty):
        flat = dirty[i]
        dirty_flag[flat] = 0
        is_frontier = False
        if visited[flat]:
            row, col = divmod(flat, cols)
            for k in range(8):
                v = neighbour_flat(row, col, k, rows, cols)
                if v >= 0 and known[v] == UNKNOWN:
                    is_frontier = True
                    break
        pos = frontier_pos[flat]
        if is_frontier and pos < 0:
            frontier_pos[flat] = n_frontier
            frontier_list[n_frontier] = flat
            n_frontier += 1
        elif not is_frontier and pos >= 0:
            last = frontier_list[n_frontier - 1]
            frontier_list[pos] = last
            frontier_pos[last] = pos
            frontier_pos[flat] = -1
            n_frontier -= 1
    state[1] = n_frontier


# --------------------------------------------------------------------------- detector


class EwfdFrontierDetector:
    """Incremental multi-robot EWFD on one shared grid (see the module docstring).

    Call :meth:`update` after integrating scans; it returns the frontier cells reachable
    from the robots, the same set as :func:`reachable_frontier_cells` on the same map.
    """

    def __init__(self, spec: GridSpec, active_radius_m: float) -> None:
        if active_radius_m <= 0:
            raise ValueError("active_radius_m must be positive")
        self.spec = spec
        self.active_radius_m = float(active_radius_m)
        # Half-side of an active square in cells: the disc's reach plus the cell holding the
        # sensor and one cell of rounding, so no cell a scan changed is left out.
        self._half_cells = math.ceil(self.active_radius_m / spec.resolution_m) + 2
        n = spec.rows * spec.cols
        self._ewfd = EwfdArrays(
            known=np.full(spec.shape, UNKNOWN, dtype=np.int8),
            visited=np.zeros(n, dtype=np.uint8),
            label=np.zeros(n, dtype=np.int64),
            parent=np.arange(64, dtype=np.int64),
            piece_active=np.zeros(64, dtype=np.int64),
            counters=np.array([1, 0], dtype=np.int64),
            changed=np.empty(n, dtype=np.int64),
            queue=np.empty(n, dtype=np.int64),
            mark=np.zeros(n, dtype=np.int64),
            dirty=np.empty(n, dtype=np.int64),
            dirty_flag=np.zeros(n, dtype=np.uint8),
            frontier_pos=np.full(n, -1, dtype=np.int64),
            frontier_list=np.empty(n, dtype=np.int64),
        )
        self._previous_robots = np.zeros(0, dtype=np.int64)
        self._first = True

    def _flat_cells(self, cells: np.ndarray) -> np.ndarray:
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        inside = self.spec.contains(cells) if len(cells) else np.zeros(0, dtype=bool)
        return np.where(inside, cells[:, 0] * self.spec.cols + cells[:, 1], -1)

    def _windows(self, scan_cells: np.ndarray | None) -> np.ndarray:
        rows, cols = self.spec.shape
        if scan_cells is None or self._first:
            return np.array([[0, rows, 0, cols]], dtype=np.int64)
        centres = np.asarray(scan_cells, dtype=np.int64).reshape(-1, 2)
        h = self._half_cells
        windows = np.stack(
            [
                np.clip(centres[:, 0] - h, 0, rows),
                np.clip(centres[:, 0] + h + 1, 0, rows),
                np.clip(centres[:, 1] - h, 0, cols),
                np.clip(centres[:, 1] + h + 1, 0, cols),
            ],
            axis=1,
        )
        return np.ascontiguousarray(windows, dtype=np.int64)

    def _reserve_ids(self, count: int) -> None:
        ewfd = self._ewfd
        needed = int(ewfd.counters[0]) + count + 1
        if needed > len(ewfd.parent):
            size = max(needed, 2 * len(ewfd.parent))
            parent = np.arange(size, dtype=np.int64)
            parent[: len(ewfd.parent)] = ewfd.parent
            self._ewfd = ewfd._replace(parent=parent, piece_active=np.zeros(size, dtype=np.int64))

    def update(
        self,
        values: np.ndarray,
        robot_cells: np.ndarray,
        scan_cells: np.ndarray | None = None,
    ) -> np.ndarray:
        """Bring the frontier set up to date with the map ``values``; returns it as (F, 2).

        ``robot_cells``: (R, 2) current ``[row, col]`` of the robots (the wavefront
        sources). ``scan_cells``: cells of the sensor poses of every scan integrated since
        the last update; the map is compared only in their active areas. Pass ``None``
        when cells may have changed anywhere (e.g. SLAM moved scans); the first update
        always compares the whole grid.
        """
        values = np.ascontiguousarray(values, dtype=np.int8)
        if values.shape != self.spec.shape:
            raise ValueError(f"values have shape {values.shape}, grid is {self.spec.shape}")
        robots = np.ascontiguousarray(self._flat_cells(robot_cells))
        if self.spec.cols % 8 == 0:
            values_words = values.view(np.uint64)
            known_words = self._ewfd.known.view(np.uint64)
        else:
            values_words = known_words = np.zeros((0, 0), dtype=np.uint64)
        n_changed, n_visited_changed = _diff(
            values, values_words, known_words, self._windows(scan_cells), self._ewfd
        )
        self._first = False
        # Ids the update may create: one per split piece (<= 8 per removed cell) and one
        # per robot.
        self._reserve_ids(8 * n_visited_changed + len(robots))
        _process(self._ewfd, n_changed, robots, self._previous_robots)
        self._previous_robots = robots
        return self.frontier_cells()

    def frontier_cells(self) -> np.ndarray:
        """Current frontier cells, (F, 2) ``[row, col]``, in no particular order."""
        flat = self._ewfd.frontier_list[: int(self._ewfd.counters[1])]
        return np.stack(np.divmod(flat, self.spec.cols), axis=1)

    def visited_mask(self) -> np.ndarray:
        """The global memory of visited cells (free cells reachable from the robots)."""
        return self._ewfd.visited.reshape(self.spec.shape).astype(bool)


def ewfd_detector(
    params: EwfdParams, *, spec: GridSpec, mapping: MappingConfig
) -> EwfdFrontierDetector:
    return EwfdFrontierDetector(spec, active_radius_m(mapping))


class NaiveFrontierDetector:
    """:func:`reachable_frontier_cells` over the whole grid at every update."""

    def update(
        self, values: np.ndarray, robot_cells: np.ndarray, scan_cells: np.ndarray | None
    ) -> np.ndarray:
        return reachable_frontier_cells(values, robot_cells)


def naive_detector(
    params: NaiveFrontierParams, *, spec: GridSpec, mapping: MappingConfig
) -> NaiveFrontierDetector:
    return NaiveFrontierDetector()
