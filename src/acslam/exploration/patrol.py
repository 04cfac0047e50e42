"""Loops through an explored map: how a run keeps driving once nothing is left to explore.

A long-running server must not slow down as the trajectory grows while the map stays the
same (SLAM's graph, loop-closure search and map composition all see more keyframes). The
patrol phase makes that measurable: after exploring, the robots drive a closed tour of
waypoints spread over the known free space, each starting at its own place on the tour so
the team stays spread out, for a set time.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from acslam.exploration.clustering import FrontierCluster
from acslam.grid import GridSpec


def patrol_waypoints(
    free: np.ndarray, spec: GridSpec, spacing_m: float, start_xy_m: np.ndarray
) -> np.ndarray:
    """(N, 2) waypoints [x, y] (m) over the free cells, in tour order.

    Farthest-point sampling from the free cell nearest ``start_xy_m`` until every free cell
    lies within ``spacing_m`` of a waypoint, then a nearest-neighbour tour from the first:
    deterministic, and the waypoints cover the free space evenly whatever its shape.
    """
    cells = np.argwhere(free)
    if not len(cells):
        return np.zeros((0, 2))
    points_m = spec.cell_to_world(cells)
    chosen = [int(np.argmin(np.linalg.norm(points_m - start_xy_m[:2], axis=1)))]
    gap_m = np.linalg.norm(points_m - points_m[chosen[0]], axis=1)
    while gap_m.max() > spacing_m:
        chosen.append(int(np.argmax(gap_m)))
        gap_m = np.minimum(gap_m, np.linalg.norm(points_m - points_m[chosen[-1]], axis=1))
    waypoints = points_m[chosen]
    tour = [0]
    left = list(range(1, len(waypoints)))
    while left:
        gaps = np.linalg.norm(waypoints[left] - waypoints[tour[-1]], axis=1)
        tour.append(left.pop(int(np.argmin(gaps))))
    return waypoints[tour]


class Patrol:
    """Each robot's place on the tour: robot ``i`` of ``R`` starts ``i / R`` of the way
    round and moves on one waypoint at a time."""

    def __init__(self, waypoints_m: np.ndarray, robot_count: int, started_s: float) -> None:
        self.waypoints_m = waypoints_m
        self.started_s = started_s
        count = len(waypoints_m)
        self._next = [(i * count) // max(robot_count, 1) for i in range(robot_count)]

    @classmethod
    def over(
        cls, free: np.ndarray, spec: GridSpec, spacing_m: float, start_xy_m: np.ndarray,
        started_s: float, robot_count: int,
    ) -> Patrol | None:  # fmt: skip
        """The patrol of the ``free`` cells (:func:`patrol_waypoints`), None if there are
        none."""
        waypoints_m = patrol_waypoints(free, spec, spacing_m, start_xy_m)
        return cls(waypoints_m, robot_count, started_s) if len(waypoints_m) else None

    def goal_m(self, robot: int) -> np.ndarray:
        """The waypoint the robot is driving to."""
        return self.waypoints_m[self._next[robot]]

    def advance(self, robot: int) -> None:
        """Go on to the next waypoint of the tour."""
        self._next[robot] = (self._next[robot] + 1) % len(self.waypoints_m)

    def goals(self, robot: int, reached: bool) -> Iterator[FrontierCluster]:
        """The robot's waypoint as a goal, or the next one if it ``reached`` its own; asked
        for another (no path to this one), the tour's next, once round at most."""
        if reached:
            self.advance(robot)
        no_cells = np.zeros((0, 2), np.int64)
        for _ in range(len(self.waypoints_m)):
            goal_m = self.goal_m(robot)
            yield FrontierCluster(no_cells, goal_m, no_cells, goal_m, 0, 0)
            self.advance(robot)
