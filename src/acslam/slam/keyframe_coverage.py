"""Where the team's keyframes already are, so a robot re-driving mapped space can open
keyframes less often (``SlamConfig.mapped_keyframe_distance_m``).

Dense keyframes pay where the map is new. On a pass through space that already holds
keyframes they only grow the graph: each adds a variable, loop closures to old keyframes
deep in the Bayes tree, and a row to every estimate read back, so the SLAM stage's cost
would follow the trajectory's length rather than the mapped area (Cartographer's pure
localisation and slam_toolbox's node spacing keep their graphs bounded the same way).

A keyframe is kept at the position of its first estimate. SLAM later moves it by
centimetres, rarely by more than a few decimetres, which shifts where the spacing
changes by as much and nothing else; so nothing here follows corrections.
"""

from __future__ import annotations

import math


class KeyframeCoverage:
    """Keyframe positions in a grid of ``radius_m`` cells, for a near-neighbour test."""

    def __init__(self, radius_m: float, min_path_m: float) -> None:
        """A position is covered by a keyframe within ``radius_m`` of it, of another
        robot, or of the same robot at least ``min_path_m`` back along its path (its
        latest keyframes are always near, and say nothing of a second pass)."""
        self.radius_m = radius_m
        self.min_path_m = min_path_m
        self._cells: dict[tuple[int, int], list[tuple[float, float, int, float]]] = {}

    def _cell(self, x_m: float, y_m: float) -> tuple[int, int]:
        return math.floor(x_m / self.radius_m), math.floor(y_m / self.radius_m)

    def add(self, robot_id: int, x_m: float, y_m: float, path_m: float) -> None:
        """A keyframe of ``robot_id`` at ``(x_m, y_m)``, ``path_m`` along its path."""
        self._cells.setdefault(self._cell(x_m, y_m), []).append((x_m, y_m, robot_id, path_m))

    def covers(self, robot_id: int, x_m: float, y_m: float, path_m: float) -> bool:
        """Whether ``robot_id``, at ``(x_m, y_m)`` and ``path_m`` along its path, is in
        space an earlier keyframe already covers."""
        cx, cy = self._cell(x_m, y_m)
        radius_sq = self.radius_m * self.radius_m
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for kx, ky, owner, owner_path_m in self._cells.get((cx + dx, cy + dy), ()):
                    if (kx - x_m) ** 2 + (ky - y_m) ** 2 > radius_sq:
                        continue
                    if owner != robot_id or owner_path_m <= path_m - self.min_path_m:
                        return True
        return False
