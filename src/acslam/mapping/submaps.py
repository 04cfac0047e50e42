"""Submap mapper: scans go into rigid local grids that SLAM corrections re-place whole.

Exact re-integration (:class:`~acslam.mapping.occupancy.TeamMap`) re-casts every beam of
every scan whose keyframe moved, so a loop closure late in a long run costs a ray cast
for much of the trajectory. Here, as in Cartographer and slam_toolbox, each robot's
consecutive scans fill a *submap*: a window of the map's grid, cell-aligned with it,
anchored to the submap's first scan. When SLAM moves an anchor, the submap is taken out
of the global and robot grids at its old placement and added at the new one, a rigid
resampling whose cost is the submap's area, whatever the number of scans in it. The
scans keep the relative poses they had when inserted (the submap is rigid); only the
anchor's corrections reach the map.

A submap takes scans while it is *open*: until ``submap_travel_m`` from its anchor,
``submap_max_scans`` scans, or its anchor's first correction. An open submap lies where
it was built, so its scans are added to the global grid directly, the same integers as
the exact mapper. Placements are exact integer sums (the fixed-point accumulators of
:mod:`acslam.mapping.occupancy`), so after any sequence of corrections the global grid
equals the composition of every submap at its current anchor pose, built from scratch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from acslam.geometry import wrap_angle
from acslam.grid import GridSpec
from acslam.mapping.occupancy import FusedGrids
from acslam.mapping.params import SubmapMappingConfig


@dataclass
class _Submap:
    robot_id: int
    built_anchor: np.ndarray
    """Anchor pose the scans were inserted at; the accumulator is in this frame."""
    placed_anchor: np.ndarray
    """Anchor pose of the submap's current placement in the global and robot grids."""
    origin_xy_m: tuple[float, float]
    accumulator: np.ndarray
    first_cell: tuple[int, int]
    """Map-grid row and column of the open window's first cell (before cropping)."""
    scans: int = 0
    open: bool = True


def rigid_transform(
    built_pose: np.ndarray, placed_pose: np.ndarray
) -> tuple[float, float, float, float]:
    """(cos, sin, tx, ty) of T = placed * built^-1, which takes a point of the built frame
    to where the placed anchor puts it. Equal poses give exactly the identity."""
    theta = wrap_angle(float(placed_pose[2]) - float(built_pose[2]))
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    bx, by = float(built_pose[0]), float(built_pose[1])
    tx = float(placed_pose[0]) - (cos_t * bx - sin_t * by)
    ty = float(placed_pose[1]) - (sin_t * bx + cos_t * by)
    return cos_t, sin_t, tx, ty


class SubmapTeamMap(FusedGrids):
    """Team map composed of rigid per-robot submaps (see the module docstring)."""

    history_free = False  # a submap keeps its scans where they were when it was built

    def __init__(self, config: SubmapMappingConfig, *, spec: GridSpec) -> None:
        super().__init__(config, spec=spec)
        self.submap_config = config
        reach_m = config.max_range_m + config.hit_radius_m + config.submap_travel_m
        # One cell of rounding either side, as for the EWFD active area.
        self._half_cells = math.ceil(reach_m / spec.resolution_m) + 2
        self._submaps: dict[int, _Submap] = {}
        """By the index of the anchor scan."""
        self._open: dict[int, int] = {}
        """Robot id -> anchor index of its open submap."""
        self._scan_count = 0

    def __len__(self) -> int:
        return self._scan_count

    @property
    def submap_count(self) -> int:
        return len(self._submaps)

    def add_scan(
        self,
        robot_id: int,
        index: int,
        ranges: np.ndarray,
        angles: np.ndarray,
        pose: np.ndarray,
        range_max_m: float = math.inf,
    ) -> None:
        """Integrate a scan at sensor ``pose`` into the map and its robot's open submap."""
        pose = np.array(pose, dtype=np.float64).reshape(3)
        submap = self._submap_for(int(robot_id), int(index), pose)
        update = self.global_grid.scan_update(ranges, angles, pose, range_max_m)
        if not self._apply(int(robot_id), update, 1, (submap.accumulator, *submap.first_cell)):
            raise ValueError(f"scan {index} changes cells outside its submap's window")
        submap.scans += 1
        self._scan_count += 1

    def move_scan(self, index: int, pose: np.ndarray) -> None:
        """Re-place the submap ``index`` anchors; other scans follow their anchor."""
        submap = self._submaps.get(int(index))
        pose = np.array(pose, dtype=np.float64).reshape(3)
        if submap is None or np.array_equal(pose, submap.placed_anchor):
            return
        self._close(int(index))
        self._place(submap, -1)
        submap.placed_anchor = pose
        self._place(submap, 1)
        self._version += 1

    # ------------------------------------------------------------------ submaps

    def _submap_for(self, robot_id: int, index: int, pose: np.ndarray) -> _Submap:
        """The robot's open submap if the scan belongs in it, else a new one it anchors."""
        anchor = self._open.get(robot_id)
        if anchor is not None:
            submap = self._submaps[anchor]
            travel_m = float(np.hypot(*(pose[:2] - submap.built_anchor[:2])))
            if (
                submap.scans < self.submap_config.submap_max_scans
                and travel_m <= self.submap_config.submap_travel_m
            ):
                return submap
            self._close(anchor)
        return self._new_submap(robot_id, index, pose)

    def _new_submap(self, robot_id: int, index: int, pose: np.ndarray) -> _Submap:
        spec, half = self.spec, self._half_cells
        row, col = spec.world_to_cell(pose[:2])[0]
        r0, c0 = max(0, row - half), max(0, col - half)
        r1, c1 = min(spec.rows, row + half + 1), min(spec.cols, col + half + 1)
        submap = _Submap(
            robot_id=robot_id,
            built_anchor=pose.copy(),
            placed_anchor=pose.copy(),
            origin_xy_m=(
                spec.origin_x_m + c0 * spec.resolution_m,
                spec.origin_y_m + r0 * spec.resolution_m,
            ),
            accumulator=np.zeros((max(r1 - r0, 0), max(c1 - c0, 0)), dtype=np.int64),
            first_cell=(int(r0), int(c0)),
        )
        self._submaps[index] = submap
        self._open[robot_id] = index
        return submap

    def _close(self, anchor: int) -> None:
        """Stop adding scans to a submap and crop it to the cells its scans touched."""
        submap = self._submaps[anchor]
        if not submap.open:
            return
        submap.open = False
        if self._open.get(submap.robot_id) == anchor:
            del self._open[submap.robot_id]
        touched_rows = np.flatnonzero(submap.accumulator.any(axis=1))
        touched_cols = np.flatnonzero(submap.accumulator.any(axis=0))
        if len(touched_rows) == 0:
            submap.accumulator = np.zeros((0, 0), dtype=np.int64)
            return
        r0, r1 = touched_rows[0], touched_rows[-1] + 1
        c0, c1 = touched_cols[0], touched_cols[-1] + 1
        submap.accumulator = np.ascontiguousarray(submap.accumulator[r0:r1, c0:c1])
        resolution_m = self.spec.resolution_m
        x0_m, y0_m = submap.origin_xy_m
        submap.origin_xy_m = (x0_m + c0 * resolution_m, y0_m + r0 * resolution_m)

    def _place(self, submap: _Submap, sign: int) -> None:
        if submap.accumulator.size == 0:
            return
        transform = rigid_transform(submap.built_anchor, submap.placed_anchor)
        self.robot_grid(submap.robot_id).place(
            submap.accumulator, submap.origin_xy_m, transform, sign
        )
        self._mark_changed(
            *self.global_grid.place(submap.accumulator, submap.origin_xy_m, transform, sign)
        )
