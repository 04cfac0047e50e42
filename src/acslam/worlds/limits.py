"""The grid a scenario's world would allocate, checked before anything is allocated.

A world's extent and cell size fix the size of every grid a run keeps (ground truth, the
team's map, frontiers, costmap, planning). Too fine a cell over too large a world asks for
more memory than a machine has; the run would die allocating it, after minutes of
building. :func:`check_world_grid` refuses such a scenario at once, naming the field that
sets the cell count, against ``sim.max_grid_cells``.

It also refuses a cell coarser than a tenth of the LiDAR's range. The thesis sets no such
bound; ours is that a cell that coarse cannot hold a wall, a door and the free space
between them within what one scan sees, so the map could not be explored, and the
figures it gives (a 1 km cell "maps" 10^12 m^2) would be meaningless.
"""

from __future__ import annotations

from pathlib import Path

from acslam.config import (
    DungeonWorld,
    FloorplanWorld,
    MapFileWorld,
    OsmWorld,
    ScenarioConfig,
    ThesisWorld,
    VineyardWorld,
    WorldConfig,
)
from acslam.errors import ConfigError
from acslam.grid import GridSpec

# Bytes per cell of the grids a run allocates over the world's extent (the costmap and
# planning grids cover the explored window, at most the world), by module.
BYTES_PER_CELL = {
    # worlds.world: occupancy and LiDAR grids (bool), clearance (float64), reachable area
    # (labels int32, mask, distance float64)
    "ground truth": 1 + 1 + 8 + 4 + 1 + 8,
    # mapping.occupancy: the team's log-odds accumulator (int64), ray-cast scratch
    # (uint8 + float64), occupancy values (int8)
    "team map": 8 + 1 + 8 + 1,
    # exploration.frontiers: EWFD's state (int8, 2 uint8, 7 int64)
    "frontiers": 1 + 2 + 7 * 8,
    # mapping.costmap: distance (float32 and float64) and cost (float64)
    "costmap": 4 + 8 + 8,
    # planning.astar: g (float64), parent (int64), closed and target flags
    "global planning": 8 + 8 + 1 + 1,
}
BYTES_PER_CELL_PER_ROBOT = 8 + 1
"""Each robot's own log-odds accumulator (int64) and the mask of what it mapped."""

MAX_CELL_FRACTION_OF_LIDAR_RANGE = 0.1


def planned_grid(world: WorldConfig) -> tuple[GridSpec, str]:
    """The grid the world's generator will allocate, from its settings and image headers
    alone, and the field that sets its cell count."""
    from acslam.worlds.dungeon import dungeon_spec
    from acslam.worlds.floorplan import floorplan_spec
    from acslam.worlds.mapio import map_spec
    from acslam.worlds.osm import osm_spec
    from acslam.worlds.thesis import thesis_spec
    from acslam.worlds.vineyard import vineyard_spec

    match world:
        case ThesisWorld():
            return thesis_spec(world), "world.resolution_m"
        case VineyardWorld():
            return vineyard_spec(world), "world.resolution_m"
        case DungeonWorld():
            return dungeon_spec(world), "world.resolution_m"
        case OsmWorld():
            return osm_spec(world), "world.resolution_m"
        case FloorplanWorld():
            return floorplan_spec(world), "world.file"
        case MapFileWorld():
            return map_spec(world.file), "world.file"
    raise TypeError(f"unknown world config {type(world).__name__}")


def grid_bytes(spec: GridSpec, robots: int) -> int:
    """Estimated bytes of every grid layer a run of ``robots`` allocates on ``spec``."""
    per_cell = sum(BYTES_PER_CELL.values()) + robots * BYTES_PER_CELL_PER_ROBOT
    return spec.rows * spec.cols * per_cell


def _size(count_bytes: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if count_bytes < 1000 or unit == "TB":
            return f"{count_bytes:.3g} {unit}"
        count_bytes /= 1000
    raise AssertionError("unreachable")


def check_world_grid(config: ScenarioConfig, source: str | Path, robots: int) -> None:
    """Refuse a world whose cells are coarser than a tenth of the LiDAR range, or whose grid
    has more than ``sim.max_grid_cells`` cells: a ConfigError naming the field."""
    spec, size_field = planned_grid(config.world)
    range_m = config.sensors.lidar.range_max_m
    if isinstance(config.world, MapFileWorld):
        resolution_source, resolution_field = config.world.file, "resolution"
    else:
        resolution_source, resolution_field = source, "world.resolution_m"
    if spec.resolution_m > MAX_CELL_FRACTION_OF_LIDAR_RANGE * range_m:
        raise ConfigError(
            resolution_source,
            resolution_field,
            f"a cell of {spec.resolution_m:g} m is coarser than a tenth of the LiDAR range "
            f"(sensors.lidar.range_max_m: {range_m:g} m)",
        )
    if spec.rows < 1 or spec.cols < 1:
        raise ConfigError(
            source, "world", f"the world is smaller than one cell of {spec.resolution_m:g} m"
        )
    cells = spec.rows * spec.cols
    budget = config.sim.max_grid_cells
    if cells > budget:
        field = size_field
        if size_field == "world.resolution_m":
            field, cause = size_field, f"cells of {spec.resolution_m:g} m make"
        else:
            cause = f"the image of {Path(config.world.file).name} makes"
        raise ConfigError(
            source,
            field,
            f"{cause} a {spec.cols} x {spec.rows} grid, {cells:.3g} cells (about "
            f"{_size(grid_bytes(spec, robots))} over the run's grid layers), above "
            f"sim.max_grid_cells ({budget:.3g}): use coarser cells or a smaller world, or "
            "raise sim.max_grid_cells",
        )
