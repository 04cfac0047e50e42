"""The built-in plugins: each stage's names, their parameter models and where their
implementations live (imported when a plugin is first built, see
:meth:`~acslam.pipeline.registry.Registry.declare`)."""

from __future__ import annotations

from acslam.config import MappingConfig, SlamConfig
from acslam.exploration.params import (
    DbscanParams,
    EwfdParams,
    FactorGraphParams,
    GreedyParams,
    HungarianParams,
    NaiveFrontierParams,
    ThesisParams,
)
from acslam.mapping.params import SubmapMappingConfig
from acslam.pipeline.registry import (
    ALLOCATORS,
    CLUSTERERS,
    FRONTIER_DETECTORS,
    GLOBAL_PLANNERS,
    LOCAL_PLANNERS,
    LOCALIZERS,
    MAPPERS,
)
from acslam.planning.params import AstarParams, DwaParams, FgpParams

LOCALIZERS.declare("isam2", SlamConfig, "acslam.slam.localizer:Isam2Localizer")
MAPPERS.declare("log-odds", MappingConfig, "acslam.mapping.occupancy:TeamMap")
MAPPERS.declare("submaps", SubmapMappingConfig, "acslam.mapping.submaps:SubmapTeamMap")
FRONTIER_DETECTORS.declare("ewfd", EwfdParams, "acslam.exploration.frontiers:ewfd_detector")
FRONTIER_DETECTORS.declare(
    "naive", NaiveFrontierParams, "acslam.exploration.frontiers:naive_detector"
)
CLUSTERERS.declare("dbscan", DbscanParams, "acslam.exploration.clustering:DbscanClusterer")
ALLOCATORS.declare("greedy", GreedyParams, "acslam.exploration.allocation:GreedyAllocator")
ALLOCATORS.declare("hungarian", HungarianParams, "acslam.exploration.allocation:HungarianAllocator")
ALLOCATORS.declare(
    "factor-graph", FactorGraphParams, "acslam.exploration.allocation:FactorGraphAllocator"
)
ALLOCATORS.declare("thesis", ThesisParams, "acslam.exploration.allocation:FactorGraphAllocator")
GLOBAL_PLANNERS.declare("astar", AstarParams, "acslam.planning.astar:AstarPlanner")
LOCAL_PLANNERS.declare("dwa", DwaParams, "acslam.planning.dwa:DynamicWindowPlanner")
LOCAL_PLANNERS.declare("fgp", FgpParams, "acslam.planning.fgp:FactorGraphPlanner")
