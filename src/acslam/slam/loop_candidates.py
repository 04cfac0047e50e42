"""Loop-closure candidates: pairs of keyframes close in space, found without comparing
every keyframe with every other at each search.

The rule is that of a search over all keyframes: a pair is a candidate when its keyframes
are within ``radius_m`` of each other now, are not neighbours in time (two robots'
keyframes, or one robot's at least ``min_separation_s`` apart) and was not tried before;
candidates are tried nearest first (ties by pair), at most ``attempts`` times per later
keyframe of a pair, ever. Such a search grows with the trajectory: with every keyframe,
and in a place passed many times with every pass.

So each keyframe sits in a grid at an *anchor*, the position it had when last placed, and
is placed again only once it drifts more than half of ``slack_m`` from it (SLAM moves
almost every keyframe a little at every update). A pair's distance then differs from its
anchors' distance by at most ``slack_m``. Each keyframe that may still be tried keeps the
earlier keyframes it could be tried with: those whose anchors are within ``radius_m +
2 slack_m`` of its own, and of those only the ones no more than ``2 slack_m`` further than
its ``b``-th nearest (``b`` its attempts left), since the ``b`` nearer ones are sure to come
first. That list is rebuilt only when the keyframe or one of its neighbours is placed
again. A search measures the kept pairs at the keyframes' exact positions. Its cost
follows what drifted and what is near; only the drift test looks at every keyframe, as
one vectorised subtraction.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

Pair = tuple[int, int]


class LoopCandidates:
    """Keyframes by index (the order of :meth:`add`), and the pairs to try."""

    def __init__(
        self,
        radius_m: float,
        min_separation_s: float,
        attempts: int,
        slack_m: float = 0.1,
        tolerance_m: float = 1e-6,
    ) -> None:
        """``tolerance_m`` bounds how far the positions given to :meth:`search` may be from
        the exact ones; it must stay well below ``slack_m``."""
        if not 0.0 <= tolerance_m < slack_m / 4:
            raise ValueError(f"tolerance_m must be in [0, slack_m / 4), got {tolerance_m}")
        if attempts < 1:
            raise ValueError(f"attempts must be >= 1, got {attempts}")
        self.radius_m = radius_m
        self.min_separation_s = min_separation_s
        self.attempts = attempts
        self.slack_m = slack_m
        self.tolerance_m = tolerance_m
        self._reach_m = radius_m + 2.0 * slack_m
        self._count = 0
        self._robots = np.zeros(64, dtype=np.int64)  # per keyframe, with spare rows
        self._stamps_s = np.zeros(64)
        self._anchors = np.zeros((0, 2))
        self._cell_of: list[tuple[int, int]] = []
        self._cells: dict[tuple[int, int], list[int]] = {}
        self._tried: set[Pair] = set()
        self._tries: dict[int, int] = {}  # later keyframe -> pairs tried
        self._kept: dict[int, set[int]] = {}  # later keyframe -> earlier keyframes kept
        self._kept_by: dict[int, set[int]] = {}  # earlier keyframe -> later ones keeping it

    def __len__(self) -> int:
        return self._count

    def add(self, robot_id: int, stamp_s: float) -> int:
        """A new keyframe; it is placed at the next :meth:`search`. Returns its index."""
        if self._count == len(self._robots):
            self._robots = np.concatenate([self._robots, self._robots])
            self._stamps_s = np.concatenate([self._stamps_s, self._stamps_s])
        self._robots[self._count] = int(robot_id)
        self._stamps_s[self._count] = float(stamp_s)
        self._count += 1
        return self._count - 1

    def search(self, positions: np.ndarray, exact: Callable[[int], np.ndarray]) -> list[Pair]:
        """The pairs to try now, in order; from here on they count as tried.

        ``positions`` is the (n, 2) position of every keyframe, each within
        ``tolerance_m`` of ``exact(k)``, the exact position: the former only decides
        which keyframes are placed again; distances and order come from the latter. A pair
        is within the radius when dx^2 + dy^2 <= radius^2, as scipy's cKDTree decides.
        """
        positions = np.asarray(positions, dtype=float).reshape(-1, 2)
        if len(positions) != self._count:
            raise ValueError(f"{len(positions)} positions for {self._count} keyframes")
        placed = len(self._anchors)
        self._anchors = np.vstack([self._anchors, positions[placed:]])
        drift_m = np.hypot(*(positions[:placed] - self._anchors[:placed]).T)
        moved = np.flatnonzero(drift_m > self.slack_m / 2.0 - self.tolerance_m).tolist()
        rescan: set[int] = set(range(placed, len(positions)))
        for k in [*moved, *range(placed, len(positions))]:
            rescan |= self._place(k, positions[k])
        for later in sorted(rescan):
            self._scan(later)
        at: dict[int, np.ndarray] = {}
        radius_sq = self.radius_m * self.radius_m
        found = []
        for later in sorted(self._kept):
            b = at[later] if later in at else at.setdefault(later, exact(later))
            for earlier in sorted(self._kept[later]):
                a = at[earlier] if earlier in at else at.setdefault(earlier, exact(earlier))
                d = a - b
                if d[0] * d[0] + d[1] * d[1] <= radius_sq:
                    found.append((float(np.hypot(*d)), (earlier, later)))
        chosen = []
        for _, pair in sorted(found):
            if self._tries.get(pair[1], 0) < self.attempts:
                self._try(pair)
                chosen.append(pair)
        return chosen

    def _cell(self, position: np.ndarray) -> tuple[int, int]:
        return math.floor(position[0] / self._reach_m), math.floor(position[1] / self._reach_m)

    def _near(self, k: int) -> np.ndarray:
        """Placed keyframes in the 3 x 3 cells around k's, other than k."""
        cx, cy = self._cell_of[k]
        near = [
            m
            for dx in (-1, 0, 1)
            for dy in (-1, 0, 1)
            for m in self._cells.get((cx + dx, cy + dy), ())
        ]
        near_array = np.array(near, dtype=np.int64)
        return near_array[near_array != k]

    def _place(self, k: int, position: np.ndarray) -> set[int]:
        """Anchor keyframe k at ``position``; returns the later keyframes whose kept
        pairs this may change (k itself, those that kept k, those now within reach)."""
        if k < len(self._cell_of):
            self._cells[self._cell_of[k]].remove(k)
            self._cell_of[k] = self._cell(position)
        else:
            self._cell_of.append(self._cell(position))
        self._cells.setdefault(self._cell_of[k], []).append(k)
        self._anchors[k] = position
        near = self._near(k)
        later = near[near > k]
        gap = self._anchors[later] - position
        later = later[gap[:, 0] ** 2 + gap[:, 1] ** 2 <= self._reach_m**2]
        affected = {k, *self._kept_by.get(k, ()), *later.tolist()}
        return {j for j in affected if self._tries.get(j, 0) < self.attempts}

    def _scan(self, later: int) -> None:
        """Rebuild the earlier keyframes ``later`` keeps (see the module docstring)."""
        self._forget(later)
        budget = self.attempts - self._tries.get(later, 0)
        if budget <= 0:
            return
        near = self._near(later)
        near = near[near < later]
        separated = (self._robots[near] != self._robots[later]) | (
            np.abs(self._stamps_s[near] - self._stamps_s[later]) >= self.min_separation_s
        )
        near = near[separated]
        gap = self._anchors[near] - self._anchors[later]
        distance_m = np.hypot(gap[:, 0], gap[:, 1])
        order = np.argsort(distance_m, kind="stable")
        kept: set[int] = set()
        limit_m = self._reach_m
        live = 0
        for m, d in zip(near[order].tolist(), distance_m[order].tolist(), strict=True):
            if d > limit_m:
                break
            if (m, later) in self._tried:
                continue
            kept.add(m)
            live += 1
            if live == budget:
                limit_m = min(limit_m, d + 2.0 * self.slack_m)
        if kept:
            self._kept[later] = kept
            for m in kept:
                self._kept_by.setdefault(m, set()).add(later)

    def _forget(self, later: int) -> None:
        for m in self._kept.pop(later, ()):
            self._kept_by[m].discard(later)

    def _try(self, pair: Pair) -> None:
        earlier, later = pair
        self._tried.add(pair)
        self._tries[later] = self._tries.get(later, 0) + 1
        if self._tries[later] >= self.attempts:
            self._forget(later)
        else:
            self._kept[later].discard(earlier)
            self._kept_by[earlier].discard(later)
            if not self._kept[later]:
                del self._kept[later]
