"""LiDAR scans as relative-pose factors of the SLAM graph (thesis §4.4.1).

The first scan of each keyframe is matched (point-to-surface ICP,
:mod:`acslam.mapping.scan_matching`) to the first scan of the robot's previous keyframe,
and to that of the keyframe about ``sequential_baseline_m`` back along its path:
sequential constraints, a laser odometry that makes landmark-poor stretches usable. A
chain of short matches alone is a random walk: along a 15 m vine row, 0.002 rad of
rotation noise per 0.3 m match drifted the heading ~0.015 rad and the row ends ~0.15 m
sideways; the longer match spans several links with one error. A keyframe serves as
the baseline of one later keyframe only: a robot turning on the spot makes a keyframe
every 0.3 rad without going anywhere, and each would otherwise be matched to the same
old scan, whose errors are one error repeated, not independent ones (on thesis-exp1
seed 1, 1 mm start priors, twenty such matches of robot 2 against one scan agreed on a
place 0.3 m off and held it there for 6 s). From time to time a
keyframe is also matched to keyframes close in space, of the same robot much earlier or
of another robot: loop closures, which tie trajectories together. Every match is
verified before it enters the graph. A loop closure must also be the only fit near its
guess (restarted to either side, the match comes back to it) and gets a Huber kernel,
because a wrong one would bend the whole map. A sequential match must also agree with the
odometry it started from (``odometry_gate_chi2``), and a baseline match with the chain of
previous-keyframe matches it spans (``baseline_chain_gate_chi2``): a baseline match that
slid to a wrong fit with a tight covariance (on thesis-exp2 seed 6 with two-keyframe
submaps, 0.15 m along the way at a 5 mm sigma) pulls the whole chain with it, and the
odometry over several keyframes is too loose to tell. With ``place_scans_by_matching``
the later scans of a keyframe are placed by a match against its first scan, not by
odometry. With ``keyframe_scans`` n > 1 a sequential or baseline match takes the first n
scans of each keyframe, merged into the reference and stacked as the query, and so is
made when the next keyframe opens: one scan's noise is what the LDS-02's matches mostly
err by, and n scans share it out. Not when a teammate was in view of either keyframe's
first scan: its shadow moves over the stacked scans.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from acslam.config import ScanMatchingConfig
from acslam.geometry import between, compose
from acslam.mapping.scan_matching import (
    PreparedScan,
    ScanMatchResult,
    ScanPoints,
    disagreement_sq,
    match_scans,
    merged_reference,
    prepare_scan,
    scan_points,
    stacked_scans,
    verify,
    with_restart_spread,
)
from acslam.messages import LidarScan
from acslam.slam.backend import SlamBackend
from acslam.slam.factors import planar_compose_jacobians
from acslam.slam.loop_candidates import LoopCandidates

MAX_LOOP_ATTEMPTS = 3
"""Loop-closure matches tried per keyframe (as the later keyframe of a pair)."""


LOOP_DRIFT_PER_M = 0.05
"""A loop closure may correct the estimate by this much per metre travelled between its
keyframes (each robot's since its known start, for two robots), if more than the config's
``max_correction_m``: laser odometry drifts ~1-3 % of the way, so a fixed bound rejects
exactly the long loops that matter most. The other checks of :func:`verify` still apply."""


@dataclass(frozen=True)
class _KeyframeScan:
    scan_index: int
    robot_id: int
    stamp_s: float
    scan: PreparedScan
    path_m: float  # the robot's path length from its start to this keyframe (estimated)


@dataclass(frozen=True)
class LoopMatch:
    """A loop-closure pair and its verified match (None: rejected)."""

    a: _KeyframeScan
    b: _KeyframeScan
    result: ScanMatchResult | None


class LidarConstraints:
    """Adds verified scan-matching factors to a :class:`SlamBackend`."""

    def __init__(self, config: ScanMatchingConfig) -> None:
        self.config = config
        self.submap_keyframes = config.submap_keyframes
        self._entries: list[_KeyframeScan] = []
        self._by_keyframe: dict[tuple[int, int], int] = {}
        self._candidates = LoopCandidates(
            config.loop_radius_m, config.loop_min_separation_s, MAX_LOOP_ATTEMPTS
        )
        self._scan_indices = np.zeros(64, dtype=np.intp)  # per entry, with spare rows
        # Loop-closure pairs found and not yet matched: (a, b, guess, max correction).
        self._queued: deque[tuple[_KeyframeScan, _KeyframeScan, np.ndarray, float]] = deque()
        self._last_baseline: dict[int, int] = {}  # robot -> keyframe last used as a baseline
        # robot -> keyframe -> its accepted match to the previous keyframe, kept back to
        # the last baseline: the chain a baseline match is checked against.
        self._steps: dict[int, dict[int, ScanMatchResult]] = {}
        self._checks_chain = (
            config.baseline_chain_gate_chi2 > 0 and config.sequential_baseline_m > 0
        )
        # robot -> keyframe -> its later scans kept for matching (keyframe_scans > 1), as
        # (scan index, returns).
        self._later_scans: dict[int, dict[int, list[tuple[int, ScanPoints]]]] = {}
        # robot -> keyframe -> its scans merged into one reference, built when first asked
        # for and kept while its later scans are (the same keyframe is the next one's
        # reference and, later, often a baseline).
        self._merged: dict[int, dict[int, PreparedScan]] = {}
        self.sequential_added = 0
        self.sequential_rejected = 0
        self.loops_added = 0
        self.loops_rejected = 0

    def add_scan(
        self,
        slam: SlamBackend,
        scan_index: int,
        scan: LidarScan,
        blind_sectors: np.ndarray | None = None,
    ) -> None:
        """Keep the first scan of each keyframe (and the next ``keyframe_scans - 1``); match
        the keyframe to the previous keyframe and to the baseline keyframe: at its first
        scan, or with ``keyframe_scans`` > 1 once the next keyframe opens and its later
        scans are in (a later scan is also placed by a match, with
        ``place_scans_by_matching``). ``blind_sectors``: where teammates blocked its view."""
        robot_id, keyframe = slam.scans.keyframe(scan_index)
        first = self._by_keyframe.get((robot_id, keyframe))
        if first is not None:
            if self.config.place_scans_by_matching:
                self._place(slam, self._entries[first], scan_index, scan)
            if self.config.keyframe_scans > 1:
                later = self._later_scans.setdefault(robot_id, {}).setdefault(keyframe, [])
                if len(later) < self.config.keyframe_scans - 1:
                    returns = scan_points(scan.angles, scan.ranges, self.config)
                    later.append((scan_index, returns))
            return
        prepared = prepare_scan(scan.angles, scan.ranges, self.config, blind_sectors)
        previous = self._by_keyframe.get((robot_id, keyframe - 1))
        path_m = 0.0
        if previous is not None:
            before = self._entries[previous]
            step = between(slam.scans.pose(before.scan_index), slam.scans.pose(scan_index))
            path_m = before.path_m + float(np.hypot(step[0], step[1]))
        if len(self._entries) == len(self._scan_indices):
            self._scan_indices = np.concatenate([self._scan_indices, self._scan_indices])
        self._scan_indices[len(self._entries)] = scan_index
        self._by_keyframe[(robot_id, keyframe)] = len(self._entries)
        self._entries.append(_KeyframeScan(scan_index, robot_id, scan.stamp, prepared, path_m))
        self._candidates.add(robot_id, scan.stamp)
        if self.config.keyframe_scans == 1:
            self._match_sequential(slam, robot_id, keyframe)
        elif previous is not None:  # the previous keyframe has all its scans now
            self._match_sequential(slam, robot_id, keyframe - 1)
            self._forget_later_scans(robot_id, keyframe - 1)

    def _match_sequential(self, slam: SlamBackend, robot_id: int, keyframe: int) -> None:
        """Match the keyframe to the previous one (or its submap) and to its baseline
        keyframe, if they exist."""
        previous = self._by_keyframe.get((robot_id, keyframe - 1))
        if previous is None:
            return
        entry = self._entries[self._by_keyframe[(robot_id, keyframe)]]
        # A keyframe's later scans are stacked only if neither keyframe's first scan saw a
        # teammate: its shadow moves over the stacked scans, which assume a still scene.
        # Stacked beside teammates, office_a's sequential matches (3 robots, seed 0, 300 s,
        # a teammate within 2 m) erred +0.74 mrad in heading on average with a median
        # squared Mahalanobis error of 6.1 (17 % beyond the 99.9 % gate); the heading
        # bias turned the whole map. First scans only: +0.18 mrad, 2.7, 1.6 %.
        stacked = self._saw_no_teammate(entry) and self._saw_no_teammate(self._entries[previous])
        query = self._keyframe_query(slam, entry, stacked)
        reference = self._submap(slam, robot_id, keyframe - 1, self.submap_keyframes, stacked)
        result = self._constrain(slam, self._entries[previous], entry, reference, query)
        self._count(result)
        if result is not None:
            if self._checks_chain:
                self._steps.setdefault(robot_id, {})[keyframe] = result
            # The span of one keyframe's odometry: what calibrates it.
            slam.calibrate_odometry(
                robot_id, self._entries[previous].stamp_s, entry.stamp_s, result.relative,
                result.covariance,
            )  # fmt: skip
        baseline = self._baseline_partner(robot_id, keyframe, entry.path_m)
        if baseline is not None:
            since = slam.scans.keyframe(baseline.scan_index)[1]
            chain = self._chain(slam, robot_id, since, keyframe)
            if stacked and not self._saw_no_teammate(baseline):
                stacked, query = False, entry.scan
            reference = self._submap(slam, robot_id, since, 1, stacked)
            self._count(self._constrain(slam, baseline, entry, reference, query, chain))
            steps = self._steps.get(robot_id, {})
            for older in [k for k in steps if k <= since]:
                del steps[older]

    @staticmethod
    def _saw_no_teammate(entry: _KeyframeScan) -> bool:
        """Whether no teammate blocked the view of the keyframe's first scan."""
        return len(entry.scan.blind_sectors) == 0

    def _keyframe_query(self, slam: SlamBackend, entry: _KeyframeScan, stacked: bool) -> ScanPoints:
        """The keyframe's first scan, and if ``stacked`` its later scans kept, stacked in
        the first scan's frame where odometry (or ``place_scans_by_matching``) put them
        (:meth:`KeyframeScans.relative`)."""
        if not stacked:
            return entry.scan
        later = self._later_scans.get(entry.robot_id, {}).get(
            slam.scans.keyframe(entry.scan_index)[1], []
        )
        return stacked_scans(
            [(np.zeros(3), entry.scan)]
            + [(slam.scans.relative(entry.scan_index, index), scan) for index, scan in later]
        )

    def _forget_later_scans(self, robot_id: int, matched: int) -> None:
        """Drop the later scans that no match will use again: those of keyframes before
        the submap of the next match and before the latest keyframe already
        ``sequential_baseline_m`` behind ``matched`` (later baseline partners are never
        older than that one)."""
        kept = self._later_scans.get(robot_id, {})
        path_m = self._entries[self._by_keyframe[(robot_id, matched)]].path_m
        oldest = matched - 1
        while (entry := self._by_keyframe.get((robot_id, oldest))) is not None and (
            path_m - self._entries[entry].path_m < self.config.sequential_baseline_m
        ):
            oldest -= 1
        oldest = min(oldest, matched - self.submap_keyframes + 1)
        merged = self._merged.get(robot_id, {})
        for keyframe in [k for k in kept if k < oldest]:
            del kept[keyframe]
            merged.pop(keyframe, None)

    def _count(self, result: ScanMatchResult | None) -> None:
        if result is None:
            self.sequential_rejected += 1
        else:
            self.sequential_added += 1

    def _chain(
        self, slam: SlamBackend, robot_id: int, since: int, now: int
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The previous-keyframe matches from keyframe ``since`` to ``now`` composed:
        relative pose and covariance. A link whose match was rejected is the current
        estimate's step with its odometry's covariance. None if the check is off."""
        if not self._checks_chain:
            return None
        steps = self._steps.get(robot_id, {})
        relative, covariance = np.zeros(3), np.zeros((3, 3))
        for keyframe in range(since + 1, now + 1):
            step = steps.get(keyframe)
            if step is not None:
                link, link_covariance = step.relative, step.covariance
            else:
                before, after = (
                    self._entries[self._by_keyframe[(robot_id, k)]].scan_index
                    for k in (keyframe - 1, keyframe)
                )
                link = between(slam.scans.pose(before), slam.scans.pose(after))
                link_covariance = slam.odometry_chain_covariance(robot_id, keyframe - 1, keyframe)
            jac_chain, jac_link = planar_compose_jacobians(relative, link)
            covariance = (
                jac_chain @ covariance @ jac_chain.T + jac_link @ link_covariance @ jac_link.T
            )
            relative = compose(relative, link)
        return relative, covariance

    def _place(
        self, slam: SlamBackend, first: _KeyframeScan, scan_index: int, scan: LidarScan
    ) -> None:
        """Place a later scan of a keyframe by matching it to the keyframe's first scan
        (odometry's placement stays if the match is not verified)."""
        guess = between(slam.scans.pose(first.scan_index), slam.scans.pose(scan_index))
        query = scan_points(scan.angles, scan.ranges, self.config)
        result = match_scans(first.scan, query, guess, self.config, guess_from_odometry=True)
        if verify(result, guess, self.config, strict=False):
            slam.scans.place(scan_index, first.scan_index, result.relative)

    def _baseline_partner(
        self, robot_id: int, keyframe: int, path_m: float
    ) -> _KeyframeScan | None:
        """The robot's latest keyframe before ``keyframe - 1`` at least
        ``sequential_baseline_m`` back along its path, if any and if no earlier keyframe
        was matched to it already."""
        baseline_m = self.config.sequential_baseline_m
        if baseline_m <= 0.0:
            return None
        used = self._last_baseline.get(robot_id, -1)
        older = keyframe - 2
        while older > used and (entry := self._by_keyframe.get((robot_id, older))) is not None:
            if path_m - self._entries[entry].path_m >= baseline_m:
                self._last_baseline[robot_id] = older
                return self._entries[entry]
            older -= 1
        return None

    def close_loops(self, slam: SlamBackend) -> int:
        """Search, then match and add every loop closure queued, at once
        (:meth:`loop_matches` without the per-job bound, then :meth:`add_loops`); returns
        how many closures were added."""
        return self.add_loops(slam, self.loop_matches(slam, search=True, bounded=False)())

    def loop_matches(
        self, slam: SlamBackend, search: bool = True, bounded: bool = True
    ) -> Callable[[], list[LoopMatch]]:
        """A job that matches queued pairs of keyframes: it reads only the keyframes'
        prepared scans and the guesses taken when the pairs were found, so it may run
        beside the control loop while the graph goes on (the closures enter it when
        :meth:`add_loops` takes them).

        ``search``: first queue the pairs not yet tried of keyframes close in space,
        nearest first and at most ``MAX_LOOP_ATTEMPTS`` per keyframe, with their guesses.
        The cap is ours: a robot that passes a place many times (or turns on the spot)
        has dozens of candidates per keyframe, and matching them all costs far more than
        the few closures each keyframe needs. The pairs are those of a search over all
        keyframes at their current poses, found in time that follows what moved and what
        is near (:mod:`acslam.slam.loop_candidates`).

        ``bounded``: the job matches at most ``loop_matches_per_cycle`` pairs (when set),
        the first queued; the rest wait for the next job (:attr:`loops_waiting`). The
        search chooses the same pairs either way: the bound only spreads their matching
        over more jobs.
        """
        if search:
            pairs = self._candidates.search(
                slam.scans.positions(self._scan_indices[: len(self._entries)]),
                lambda k: slam.scans.pose(self._entries[k].scan_index)[:2],
            )
            for earlier, later in pairs:
                a, b = self._entries[earlier], self._entries[later]
                guess = between(slam.scans.pose(a.scan_index), slam.scans.pose(b.scan_index))
                way_m = (
                    a.path_m + b.path_m if a.robot_id != b.robot_id else abs(b.path_m - a.path_m)
                )
                limit_m = max(self.config.max_correction_m, LOOP_DRIFT_PER_M * way_m)
                self._queued.append((a, b, guess, limit_m))
        per_job = self.config.loop_matches_per_cycle
        count = per_job if bounded and per_job > 0 else len(self._queued)
        tries = [self._queued.popleft() for _ in range(min(count, len(self._queued)))]
        return lambda: [
            LoopMatch(a, b, self._match_loop(a, b, guess, limit_m))
            for a, b, guess, limit_m in tries
        ]

    @property
    def loops_waiting(self) -> int:
        """Loop-closure pairs found and not yet handed to a job (:meth:`loop_matches`)."""
        return len(self._queued)

    def add_loops(self, slam: SlamBackend, matches: list[LoopMatch]) -> int:
        """Add the verified loop closures of a :meth:`loop_matches` job to the graph;
        returns how many."""
        added = 0
        for match in matches:
            if match.result is None:
                self.loops_rejected += 1
                continue
            slam.scans.add_constraint(
                match.a.scan_index,
                match.b.scan_index,
                match.result.relative,
                match.result.covariance,
                True,
            )
            added += 1
        self.loops_added += added
        return added

    def _match_loop(
        self, a: _KeyframeScan, b: _KeyframeScan, guess: np.ndarray, limit_m: float
    ) -> ScanMatchResult | None:
        """Match b to a from ``guess``: the match if verified and, restarted to either
        side, it comes back (its covariance then holds any other fit as good)."""
        result = match_scans(a.scan, b.scan, guess, self.config, guess_from_odometry=False)
        if not verify(result, guess, self.config, strict=True, max_correction_m=limit_m):
            return None
        result = with_restart_spread(a.scan, b.scan, result, self.config)
        if not verify(result, guess, self.config, max_correction_m=limit_m):
            return None
        return result

    def _submap(
        self, slam: SlamBackend, robot_id: int, last: int, keyframes: int, stacked: bool
    ) -> PreparedScan:
        """Scans of keyframes ``last - keyframes + 1 .. last`` of one robot, if ``stacked``
        the later scans kept of each too, in the sensor frame of ``last`` (just ``last``'s
        first scan when that is all). A keyframe's scans are placed by their offsets within
        it (:meth:`KeyframeScans.relative`), keyframes by their estimates; so one
        keyframe's merged scans are the same whenever built, and are built once."""
        base = self._entries[self._by_keyframe[(robot_id, last)]]
        kept = self._later_scans.get(robot_id, {}) if stacked else {}
        if keyframes == 1 and not kept.get(last):
            return base.scan
        merged = self._merged.setdefault(robot_id, {})
        if keyframes == 1 and last in merged:
            return merged[last]
        base_pose = slam.scans.pose(base.scan_index)
        scans = []
        for keyframe in range(last, max(last - keyframes, -1), -1):
            entry = self._by_keyframe.get((robot_id, keyframe))
            if entry is None:
                continue
            first = self._entries[entry]
            placed = between(base_pose, slam.scans.pose(first.scan_index))
            # Newest first: the voxel filter keeps a cell's first return.
            for index, later in reversed(kept.get(keyframe, [])):
                scans.append((compose(placed, slam.scans.relative(first.scan_index, index)), later))
            scans.append((placed, first.scan))
        reference = merged_reference(scans, self.config)
        if keyframes == 1:
            merged[last] = reference
        return reference

    def _constrain(
        self,
        slam: SlamBackend,
        a: _KeyframeScan,
        b: _KeyframeScan,
        reference: PreparedScan,
        query: ScanPoints,
        chain: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> ScanMatchResult | None:
        """Match ``query`` (returns in b's frame) to ``reference`` (in a's frame), of
        keyframes a and b of one robot, and add the factor between them if the match is
        verified and agrees with the odometry between them and with ``chain`` (the composed
        matches between them, as relative pose and covariance), if given; returns the
        match, or None if it was not added."""
        guess = between(slam.scans.pose(a.scan_index), slam.scans.pose(b.scan_index))
        result = match_scans(reference, query, guess, self.config, guess_from_odometry=True)
        robot_id, since = slam.scans.keyframe(a.scan_index)
        odometry_covariance = slam.odometry_chain_covariance(
            robot_id, since, slam.scans.keyframe(b.scan_index)[1]
        )
        if not verify(
            result, guess, self.config, strict=False, guess_covariance=odometry_covariance
        ):
            return None
        if chain is not None and not (
            disagreement_sq(result, *chain) <= self.config.baseline_chain_gate_chi2
        ):
            return None
        slam.scans.add_constraint(
            a.scan_index, b.scan_index, result.relative, result.covariance, False
        )
        return result
