"""What the server has decided after a step: the one thing runner, metrics, live view
and transport read.

A snapshot is immutable and cheap: poses and decisions are small copies, while the map
and the trajectories are read-only views into the stages (no grid is copied every
control period). A view reads the stage when asked, so read it before the next step, or
compare ``map.version`` to see whether the map changed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from acslam.exploration.clustering import FrontierCluster
from acslam.grid import Window
from acslam.mapping.costmap import Costmap
from acslam.messages import VelocityCommand
from acslam.pipeline.stages import Mapper

if TYPE_CHECKING:
    from acslam.pipeline.frames import FrameMerge, FrameView


@dataclass(frozen=True)
class MapView:
    """The team map as of ``version``."""

    version: int
    _mapper: Mapper

    def occupancy_values(self) -> np.ndarray:
        """Read-only grid of -1 (unknown), 0 (free), 100 (occupied)."""
        return self._mapper.occupancy_values()

    def known_mask(self) -> np.ndarray:
        return self._mapper.known_mask()

    def robot_known_mask(self, robot_id: int) -> np.ndarray:
        return self._mapper.robot_known_mask(robot_id)


class Estimates(Protocol):
    """What a localization view reads: a localizer, or the frames of a team with unknown
    starts."""

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]: ...

    def landmarks(self) -> np.ndarray: ...


@dataclass(frozen=True)
class LocalizationView:
    """The estimated trajectories and landmarks."""

    _localizer: Estimates

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        """Stamps (N,) and poses (N, 3)."""
        return self._localizer.trajectory(robot_id)

    def landmarks(self) -> np.ndarray:
        return self._localizer.landmarks()


@dataclass(frozen=True)
class Snapshot:
    """The server's state after the step at ``time_s``.

    Per robot (index = robot id): ``poses`` (N, 3) estimated ``[x, y, theta]`` in the
    robot's frame ``robot_frames[i]`` (every robot is in ``"map"`` while the team shares
    one frame), ``goals_m`` and ``paths_m`` (None when it has none), ``idle_since_s``
    (None while it has a goal), ``stuck_events``. ``lost``: robot -> time it was lost.
    ``costmap`` covers ``window`` of the map grid; ``frontier_cells`` are cells of the
    whole grid, ``clusters`` cells of the window. ``timings_s``: wall seconds of each
    stage that ran in this step, and of the whole ``cycle``. ``explored_s``: when the team
    had nothing left to explore (None before); ``finished`` follows it, or the end of the
    patrol after it (``ServerConfig.patrol_s``).

    With unknown relative starts (:mod:`acslam.pipeline.frames`), ``map``, ``costmap``,
    ``window``, ``frontier_cells`` and ``clusters`` are those of robot 0's frame;
    ``frames`` holds every frame and ``merges`` every merge so far (both empty when the
    team shares one frame from the start).
    """

    time_s: float
    commands: tuple[VelocityCommand, ...]
    poses: np.ndarray
    robot_frames: tuple[str, ...]
    map: MapView
    localization: LocalizationView
    costmap: Costmap | None
    window: Window | None
    frontier_cells: np.ndarray
    clusters: tuple[FrontierCluster, ...]
    goals_m: tuple[np.ndarray | None, ...]
    paths_m: tuple[np.ndarray | None, ...]
    idle_since_s: tuple[float | None, ...]
    stuck_events: tuple[int, ...]
    lost: Mapping[int, float]
    finished: bool
    explored_s: float | None
    timings_s: Mapping[str, float]
    frames: tuple[FrameView, ...] = ()
    merges: tuple[FrameMerge, ...] = ()
