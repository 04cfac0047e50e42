"""Mapping (thesis §4.4.3): log-odds occupancy grids from posed scans, and costmaps."""

from acslam.mapping.costmap import LETHAL_COST, Costmap, compute_costmap
from acslam.mapping.occupancy import (
    FIXED_POINT_SCALE,
    LogOddsGrid,
    ScanUpdate,
    TeamMap,
    grid_spec_for_bounds,
)

__all__ = [
    "FIXED_POINT_SCALE",
    "LETHAL_COST",
    "Costmap",
    "LogOddsGrid",
    "ScanUpdate",
    "TeamMap",
    "compute_costmap",
    "grid_spec_for_bounds",
]
