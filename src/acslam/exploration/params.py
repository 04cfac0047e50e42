"""What a scenario may set of the frontier detectors, the clusterer and the allocators.

These models are all that validating a scenario needs, so it imports none of the
algorithms (nor GTSAM, numba or SciPy); each is declared to its registry with the
``module:attribute`` of its implementation, imported when the plugin is first built.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from acslam.config import FiniteFloat, NonNegativeFloat, PositiveFloat, StageParams
from acslam.pipeline.registry import ALLOCATORS, CLUSTERERS, FRONTIER_DETECTORS


@CLUSTERERS.declare("acslam.exploration.clustering:DbscanClusterer")
class DbscanParams(StageParams):
    """DBSCAN clustering of frontier cells (thesis §4.5)."""

    name: Literal["dbscan"] = "dbscan"
    eps_m: PositiveFloat = 0.3
    min_points: Annotated[int, Field(ge=1)] = 5
    # Cells a robot may stand on (outside the lethal band) a cluster needs.
    min_cluster_size: Annotated[int, Field(ge=1)] = 5
    # Information gain = unknown cells within this radius of a cluster's target cell: the
    # LiDAR's 8 m range (LidarConfig.range_max_m), what one scan from there could reveal.
    information_gain_radius_m: PositiveFloat = 8.0


@FRONTIER_DETECTORS.declare("acslam.exploration.frontiers:ewfd_detector")
class EwfdParams(StageParams):
    """EWFD has no parameters of its own: its active area follows the mapper's reach."""

    name: Literal["ewfd"] = "ewfd"


@FRONTIER_DETECTORS.declare("acslam.exploration.frontiers:naive_detector")
class NaiveFrontierParams(StageParams):
    """The full-grid scan: the reference EWFD is checked against, and a baseline."""

    name: Literal["naive"] = "naive"


DistanceMetric = Literal["path", "travel-graph", "euclidean", "euclidean-unchecked"]


class TravelParams(StageParams):
    """How every built-in allocator measures d, the travel to a cluster."""

    # A robot's current goal counts this much closer when re-allocating: switching is
    # worth it only for a frontier > 2 m nearer (about 10 s of driving at 0.22 m/s).
    commitment_m: NonNegativeFloat = 2.0
    # "path" = costmap path length from one Dijkstra per robot (walls respected;
    # unreachable clusters excluded), "travel-graph" = the same through the coarse graph
    # of planning.travel_graph (exact reachability, lengths within a few per cent, cost
    # bounded in big buildings), "euclidean" = straight line where a path exists,
    # "euclidean-unchecked" = straight line, no Dijkstra (the thesis's d).
    distance_metric: DistanceMetric = "path"
    # The travel graph's block side (rounded to whole cells, at least one), and how
    # many blocks around each robot and target are searched cell by cell.
    travel_block_m: PositiveFloat = 0.2
    travel_end_blocks: Annotated[int, Field(ge=1)] = 1
    # Dijkstra step cost = metres * (1 + weight * cell cost); 0 makes d a plain length in
    # metres, the unit alpha is stated in.
    path_cost_weight: NonNegativeFloat = 0.0
    # A robot localised in a lethal cell (inflation band) starts from the nearest free
    # cell within this radius, as the global planner's max_snap_m.
    start_snap_m: NonNegativeFloat = 0.5


class UtilityParams(TravelParams):
    """Travel against gain: the unary log-factor -alpha d + beta s (eq. 4.40)."""

    # alpha per metre of travel, beta per frontier cell, so with these values 20
    # frontier cells (1 m at 0.05 m) are worth 1 m.
    alpha: NonNegativeFloat = 1.0
    beta: NonNegativeFloat = 0.05
    # s of eq. 4.40: the cluster's frontier cells ("size"), or the unknown cells within
    # sensor range of its target ("information_gain", scale beta down accordingly).
    utility: Literal["size", "information_gain"] = "size"


@ALLOCATORS.declare("acslam.exploration.allocation:GreedyAllocator")
class GreedyParams(TravelParams):
    """Nearest robot-cluster pairs first, by travel alone: the simplest baseline, blind
    to how much a cluster would reveal."""

    name: Literal["greedy"] = "greedy"


@ALLOCATORS.declare("acslam.exploration.allocation:HungarianAllocator")
class HungarianParams(UtilityParams):
    """Distinct clusters for the robots maximising the total utility of eq. 4.40 (a
    linear assignment): the baseline the factor graph is compared with."""

    name: Literal["hungarian"] = "hungarian"


@ALLOCATORS.declare("acslam.exploration.allocation:FactorGraphAllocator")
class FactorGraphParams(UtilityParams):
    """The discrete factor graph of thesis §4.6: utilities and a pairwise sharing penalty."""

    name: Literal["factor-graph"] = "factor-graph"
    # Pairwise factor e^lambda if two robots share a cluster, e otherwise (eq. 4.41): a
    # shared cluster costs 1 - lambda in log units, metres of travel at alpha = 1 per m.
    # Ours is 20 m, the span of the thesis labs: two robots share a cluster only when no
    # other is within 20 m more of travel, or there are fewer clusters than robots (where
    # the Hungarian baseline also sends the robots left over to their best cluster). The
    # thesis's lambda << 1 (0.01, the ``thesis`` allocator) prices sharing at ~1 m, so
    # robots crowd one frontier: over 10 seeds on experiments 1-5 with 3 robots it
    # explored 2-31 % slower than Hungarian; 20 m is 3 % faster on experiment 4 and at
    # most 2.3 % slower on experiments 1-3, but 11.5 % slower on experiment 5
    # (examples/grids/allocators-10-seeds.yaml).
    conflict_lambda: FiniteFloat = -19.0
    # Exact max-product costs ~1 us per joint assignment (measured: 3 robots x 20
    # clusters 4 ms, 6x6 41 ms, 5x10 80 ms, 7x7 1.2 s): above 50 000 joint assignments
    # (~50 ms) the approximate solver (greedy + pairwise local repair) is used.
    exact_max_joint_assignments: Annotated[int, Field(ge=1)] = 50_000


@ALLOCATORS.declare("acslam.exploration.allocation:FactorGraphAllocator")
class ThesisParams(FactorGraphParams):
    """The factor graph as the thesis states it: d is the straight line, unchecked, and
    sharing a cluster costs ~1 m (lambda << 1)."""

    name: Literal["thesis"] = "thesis"
    distance_metric: DistanceMetric = "euclidean-unchecked"
    conflict_lambda: FiniteFloat = 0.01
