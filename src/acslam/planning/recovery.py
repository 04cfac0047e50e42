"""Getting unstuck: stuck detection, a back-off manoeuvre and a replan around the trap.

DWA and FGP are both local optimisers: facing a dead end (a U-shaped obstacle between a
robot and its lookahead point) they settle where the pull of the goal and the push of
the walls cancel, and stay there. Per robot, :class:`Recovery`

1. feeds a :class:`~acslam.planning.stuck.StuckDetector` with the distance to go along
   the global path;
2. on a stuck event remembers the robot's position as a trap and overrides the local
   planner: reverse ``recovery_back_off_m`` straight back at ``recovery_back_off_mps``
   (the robot drove in forward, so the way back is free; in the pocket of a dead end
   there is no room to turn), giving up after twice the nominal time if blocked;
3. then asks the caller to replan A* on :func:`penalize` d costs (higher within
   ``recovery_penalty_radius_m`` of every trap, so a global path that led into a dead
   end the map does not show leads elsewhere) and to drop the local planner's warm
   start. Turning toward the new path is the local planner's job (FGP turns in place
   before it drives, :mod:`~acslam.planning.fgp`).

Stuck events are counted (:attr:`Recovery.count`) for the metrics. None of this imports
the simulator: the server drives it from estimated poses.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from acslam.config import PlanningConfig
from acslam.grid import GridSpec
from acslam.planning.field import RobotState
from acslam.planning.stuck import StuckDetector, StuckEvent


@dataclass(frozen=True)
class RecoveryStep:
    """What to do this control period.

    ``command``: ``(v, omega)`` overriding the local planner, or None to use it.
    ``replan``: replan the global path now on penalised costs and reset the local
    planner's warm start. ``event``: the stuck event that started a recovery, if any.
    """

    command: tuple[float, float] | None
    replan: bool = False
    event: StuckEvent | None = None


class Recovery:
    """Stuck detection and recovery for one robot (see the module docstring)."""

    def __init__(self, planning: PlanningConfig) -> None:
        self.planning = planning
        self.detector = StuckDetector(planning.stuck_timeout_s, planning.stuck_min_progress_m)
        self.traps_xy_m: list[np.ndarray] = []
        self._back_off_from: tuple[float, np.ndarray] | None = None

    @property
    def count(self) -> int:
        """Stuck events so far (kept across goals)."""
        return self.detector.count

    @property
    def active(self) -> bool:
        """True while the back-off manoeuvre runs."""
        return self._back_off_from is not None

    def reset(self, stamp_s: float) -> None:
        """New goal: forget the traps and any manoeuvre; the event count is kept."""
        self.detector.reset(stamp_s)
        self.traps_xy_m.clear()
        self._back_off_from = None

    def replanned(self, stamp_s: float, new_goal: bool, distance_to_goal_m: float) -> None:
        """A new global path: to a new goal starts afresh (traps forgotten); to the same
        goal keeps the traps and the stuck timer (:meth:`StuckDetector.rebase`)."""
        if new_goal:
            self.reset(stamp_s)
        else:
            self.detector.rebase(distance_to_goal_m)

    def step(self, stamp_s: float, state: RobotState, distance_to_goal_m: float) -> RecoveryStep:
        """Feed one control period's estimated state and its distance to the goal.

        Pass the distance along the global path
        (:func:`~acslam.planning.astar.remaining_length_m`): going around an obstacle
        raises the straight-line distance, which would look like no progress.
        """
        p = self.planning
        reverse = (-p.recovery_back_off_mps, 0.0)
        if self._back_off_from is not None:
            since_s, from_xy_m = self._back_off_from
            backed_m = float(np.linalg.norm(state.xy_m - from_xy_m))
            timed_out = stamp_s - since_s >= 2.0 * p.recovery_back_off_m / p.recovery_back_off_mps
            if backed_m < p.recovery_back_off_m and not timed_out:
                return RecoveryStep(reverse)
            self._back_off_from = None
            self.detector.reset(stamp_s)
            return RecoveryStep(None, replan=True)
        event = self.detector.update(stamp_s, distance_to_goal_m)
        if event is None:
            return RecoveryStep(None)
        self.traps_xy_m.append(state.xy_m)
        self._back_off_from = (stamp_s, state.xy_m)
        return RecoveryStep(reverse, event=event)


def penalize(
    cost: np.ndarray, grid: GridSpec, traps_xy_m: Sequence[np.ndarray], planning: PlanningConfig
) -> np.ndarray:
    """The costmap cost with ``recovery_penalty_cost`` added near each of a robot's traps
    (:attr:`Recovery.traps_xy_m`, or a copy taken when a replan was scheduled): a copy if
    there are traps, ``cost`` itself if not.

    Lethal cells stay lethal and nothing becomes lethal, so a path still exists
    through a trap when it is the only way. Only the cells of a trap's bounding box are
    measured: a building's window has millions of cells, a trap's disc a few hundred.
    """
    if not traps_xy_m:
        return cost
    penalised = np.array(cost, dtype=float)
    radius_m = planning.recovery_penalty_radius_m
    reach_cells = math.ceil(radius_m / grid.resolution_m) + 1
    for trap in traps_xy_m:
        row, col = grid.world_to_cell(trap)[0]
        r0, r1 = max(row - reach_cells, 0), min(row + reach_cells + 1, grid.rows)
        c0, c1 = max(col - reach_cells, 0), min(col + reach_cells + 1, grid.cols)
        if r0 >= r1 or c0 >= c1:
            continue
        rows, cols = np.mgrid[r0:r1, c0:c1]
        centres = grid.cell_to_world(np.column_stack([rows.ravel(), cols.ravel()]))
        near = np.linalg.norm(centres - trap, axis=-1) <= radius_m
        penalised[r0:r1, c0:c1][near.reshape(r1 - r0, c1 - c0)] += planning.recovery_penalty_cost
    return penalised
