"""What each stage of the server must do: one protocol per stage kind.

The server calls nothing else on a stage, so any class with these methods can replace a
built-in one (:mod:`acslam.pipeline.registry` says how to register it). Each protocol's
docstring lists the keyword context its class is built with, after its ``params``.

Poses, paths and goals are ``[x, y, theta]`` / ``[x, y]`` in the frame of the robot they
belong to; no stage may assume that all robots share one frame. Grid cells are
``[row, col]`` of the grid (or window) they are given with.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, TypeAlias, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from acslam.exploration.allocation import Allocation
    from acslam.exploration.clustering import FrontierCluster
    from acslam.grid import GridSpec
    from acslam.mapping.costmap import Costmap
    from acslam.messages import (
        LandmarkObservations,
        LidarScan,
        OdometryIncrement,
        RobotSighting,
    )
    from acslam.planning.field import DistanceField, RobotState


# Shorthands of the signatures below (for type checkers: they are names, not classes).
Cells: TypeAlias = "np.ndarray"  # (N, 2) [row, col]
Grid: TypeAlias = "np.ndarray"  # (rows, cols) per cell
Xy: TypeAlias = "np.ndarray"  # [x, y] in metres
Xys: TypeAlias = "np.ndarray"  # (N, 2) [x, y] in metres
Clusters: TypeAlias = "Sequence[FrontierCluster]"
Goals: TypeAlias = "Sequence[int | None] | None"  # per robot, the cluster it heads to
Team: TypeAlias = "Sequence[RobotState]"
Commands: TypeAlias = "list[tuple[float, float]]"  # (v m/s, omega rad/s) per robot


@dataclass(frozen=True)
class AssociationResult:
    """What one observed point became: its most probable landmark and all probabilities.

    ``landmark`` is -1 (and ``probabilities`` empty) for a point that made no factor: an
    ambiguous point that was dropped, or (``tentative`` True) an observation of a
    tentative landmark not confirmed yet (its factor is added if it gets confirmed).
    """

    landmark: int
    is_new: bool
    probabilities: dict[int, float]
    tentative: bool = False


@runtime_checkable
class Localizer(Protocol):
    """SLAM for the team. Context: ``scan_matching`` (ScanMatchingConfig), ``starts``
    (robot id -> start pose), and from the server ``jobs`` (:mod:`acslam.pipeline.jobs`:
    where work that may run beside the control loop, such as loop-closure matching, goes;
    a replay passes none and the work runs at once).

    Scans it keeps are numbered: the index names the scan to the mapper, and
    :meth:`scan_pose` / :meth:`moved_scans` tell where it lies now.
    """

    def add_odometry(self, message: OdometryIncrement) -> None: ...

    def add_landmarks(self, message: LandmarkObservations) -> list[AssociationResult]:
        """What each point became: a landmark, a tentative one, or nothing (dropped)."""
        ...

    def add_sighting(self, message: RobotSighting) -> None: ...

    def add_scan(self, message: LidarScan) -> int | None:
        """Index of the scan, or None if it is not kept (no pose for its stamp yet)."""
        ...

    def match_scan(self, index: int, scan: LidarScan, blind_sectors: np.ndarray) -> None:
        """Keep ``scan`` (the mappable beams) as scan ``index`` and constrain it by
        matching; ``blind_sectors`` (K, 3) ``[from_rad, to_rad, range_m]``: where teammates
        blocked its view."""
        ...

    def optimize(self, close_loops: bool) -> None:
        """Add what arrived to the estimate; search loop closures first if asked."""
        ...

    def latest_pose(self, robot_id: int) -> np.ndarray: ...

    def scan_pose(self, index: int) -> np.ndarray: ...

    def moved_scans(self) -> list[int]:
        """Scans whose pose changed since they were last reported, in index order."""
        ...

    def finish(self) -> None:
        """The data has ended (a replay): a last loop search and a settled estimate."""
        ...

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (N,) and poses (N, 3) of the robot's estimated trajectory."""
        ...

    def landmarks(self) -> np.ndarray:
        """(M, 3) estimated landmark positions."""
        ...

    def diagnostics(self) -> dict:
        """Counters worth reporting (JSON-able): matches, rejections, skipped messages."""
        ...


@runtime_checkable
class Mapper(Protocol):
    """The team's occupancy map. Context: ``spec`` (GridSpec of the map)."""

    history_free: bool
    """The map depends only on each scan's latest pose, not on the adds and moves that
    led there: a server catching up on old messages may then add each scan once, at the
    end (:meth:`~acslam.pipeline.server.Server.catch_up`)."""

    @property
    def version(self) -> int:
        """Counts changes: equal versions mean an equal map."""
        ...

    def __len__(self) -> int:
        """Scans in the map."""
        ...

    def add_scan(
        self,
        robot_id: int,
        index: int,
        ranges_m: np.ndarray,
        angles_rad: np.ndarray,
        pose: np.ndarray,
        range_max_m: float,
    ) -> None:
        """A scan at its sensor ``pose``; returns beyond ``range_max_m`` are no returns."""
        ...

    def move_scan(self, index: int, pose: np.ndarray) -> None: ...

    def occupancy_values(self) -> np.ndarray:
        """Read-only grid of -1 (unknown), 0 (free), 100 (occupied)."""
        ...

    def known_mask(self) -> np.ndarray: ...

    def robot_known_mask(self, robot_id: int) -> np.ndarray:
        """Cells robot ``robot_id``'s own scans observed."""
        ...


@runtime_checkable
class FrontierDetector(Protocol):
    """Frontier cells of the map. Context: ``spec`` (GridSpec), ``mapping``
    (the mapper's params: how far a scan can change the map)."""

    def update(
        self, values: np.ndarray, robot_cells: np.ndarray, scan_cells: np.ndarray | None
    ) -> np.ndarray:
        """(n, 2) frontier cells reachable from the robots; ``scan_cells`` are the cells of
        the scans integrated since the last call, or None when the whole map may have
        changed (a pose correction)."""
        ...


@runtime_checkable
class Clusterer(Protocol):
    """Groups frontier cells into goals. No context."""

    @property
    def linkage_m(self) -> float:
        """Targets of one cluster over successive updates move less than this."""
        ...

    def cluster(
        self,
        frontier_cells: np.ndarray,
        values: np.ndarray,
        spec: GridSpec,
        costmap: Costmap,
    ) -> list[FrontierCluster]: ...


@runtime_checkable
class Allocator(Protocol):
    """Which robot explores which cluster. No context."""

    def allocate(
        self, robot_cells: Cells, clusters: Clusters, costmap: Costmap, current: Goals = None
    ) -> Allocation:
        """``current[i]``: the cluster robot i is heading to, if any."""
        ...


@runtime_checkable
class GlobalPlanner(Protocol):
    """A path for one robot on the costmap. No context. The server plans the robots'
    paths side by side on threads, so ``plan`` must not change shared state."""

    def plan(self, cost: Grid, lethal: Grid, spec: GridSpec, start_xy_m: Xy, goal_xy_m: Xy) -> Xys:
        """(M, 2) waypoints after the start, ending at the goal; raises
        :class:`~acslam.errors.NoPathError` when there is none."""
        ...


@runtime_checkable
class LocalPlanner(Protocol):
    """Velocity commands for the whole team at once. Context: ``planning``
    (PlanningConfig), ``robots`` (RobotsConfig)."""

    def plan(self, states: Team, goals_xy_m: Sequence[Xy], field: DistanceField) -> Commands:
        """``(v, omega)`` per robot toward its lookahead point."""
        ...

    def reset(self, robot_id: int) -> None:
        """Forget what was kept for a robot (a new goal, a lost robot)."""
        ...
