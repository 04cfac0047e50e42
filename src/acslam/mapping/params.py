"""Parameters of the mapper plugins, apart from their code.

Validating a scenario needs only these models, so it imports no algorithm (and none of
GTSAM, numba or SciPy): each model is declared to its registry with the implementation,
which is imported when the plugin is first built.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from acslam.config import MappingConfig, PositiveFloat
from acslam.pipeline.registry import MAPPERS


@MAPPERS.declare("acslam.mapping.submaps:SubmapTeamMap")
class SubmapMappingConfig(MappingConfig):
    """The ``submaps`` mapper: the log-odds model plus how scans are grouped.

    A submap holds at most ``submap_max_scans`` scans (a cell gets one update per scan,
    so this also bounds a submap's accumulator) and the scans taken within
    ``submap_travel_m`` of its anchor.
    """

    name: Literal["submaps"] = "submaps"
    submap_travel_m: PositiveFloat = 2.0
    submap_max_scans: Annotated[int, Field(ge=1)] = 100


MAPPERS.declare("acslam.mapping.occupancy:TeamMap")(MappingConfig)
