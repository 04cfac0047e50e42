"""Robots whose relative start poses are unknown (``robots.relative_starts: unknown``): one
frame per robot until the data places them, then one frame for the robots merged.

Each robot starts at the origin of its own frame, and nothing tells the server where that
frame lies. Until it is merged, a robot has a server of its own
(:class:`~acslam.pipeline.server.Server`): its SLAM, its map, its frontiers and its plans.
Two frames are placed by two kinds of evidence together: a robot of one seen by a robot
of the other, and their maps' overlap. Every ``merge_period_s``, wherever a robot's scan
shows a small object standing where its map is free (perhaps a robot of another frame),
each robot of each other frame is tried there: its frame's walls within ``PIN_REACH_M``
of it are matched, at every heading, against the seeing frame's map, with the robot held
within ``PIN_HALF_SIZE_M`` of the object (:func:`~acslam.mapping.merge.find_merge` with a
:class:`~acslam.mapping.merge.Pin`, accepted only when verified). The sighting leaves a
search of about a square metre instead of the whole map. A search of the whole map took
up to 143 s in one cycle on an office floor, where one place looks like another, and was
of no use until the robots met, since a match must be borne out by sightings anyway: over
9 runs of random starts (dungeon, thesis-exp5, IPA lab), 17 of the 18 merges came as
early or earlier pinned (one 4 s later), and IPA office_e, which the whole-map search had
not merged in 646 s, merged at 334 s and 840 s.

A wrong merge is worse than a late one: two robots that each saw one room of a dungeon
matched the rooms 13 m apart, and in an office floor of like offices (IPA office_e) a
match 24 m off kept gaining matched walls as both robots explored. So a match is only a
candidate until the robots' LiDARs bear it out (:func:`sighting`). Where the candidate
puts a robot of the other frame in a robot's view, a small object must stand; a scan that
runs through that place refutes the candidate. Robots seen where it puts them at places
``SIGHTINGS_APART_M`` apart confirm it: a pillar or a door frame can pass for a robot
once (in office_e one did, and merged a frame 10 m off), but does not move with it.

A merge refines the pose (on the maps' own cells, then between cells) and builds
one server for both frames' robots, in the frame of the lower robot id: the other frame's
starts carried through the pose, and every message its robots sent replayed into the new
server's SLAM and map (:meth:`~acslam.pipeline.server.Server.catch_up`), so the merged
frame holds what a run with those starts would have made. Allocation and planning then
split the frontiers between the merged robots and keep them apart.

Each frame's grid is a square about its origin, twice the diagonal of the deployment's
map extent wide: wherever in that extent a robot started and whichever way it faced, its
frame's grid holds the whole building, so no guess of where it is was needed.

A robot of another frame is unknown to a frame's server: the returns of its robots' latest
scans that the map does not explain are obstacles to their local planner
(``scan_obstacles``), refreshed with every scan.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from functools import partial
from types import MappingProxyType

import numpy as np
from scipy.spatial.distance import pdist

from acslam.config import ScenarioConfig
from acslam.geometry import between, compose, transform_points, wrap_angle, wrap_angles
from acslam.grid import GridSpec
from acslam.mapping.costmap import known_window
from acslam.mapping.merge import MergeDecision, Pin, coarsened, find_merge, on_finer_cells
from acslam.messages import LidarScan, RobotMessage, VelocityCommand
from acslam.pipeline.jobs import InlineJobs, Jobs
from acslam.pipeline.server import Server
from acslam.pipeline.snapshot import LocalizationView, Snapshot
from acslam.schedule import Periodic

SEARCH_RESOLUTION_M = 0.1
"""Frames are searched for a merge on 0.1 m cells: a search of two floor-plan maps on
0.05 m cells took 0.43 s per branch and bound, and a merge's pose is refined after
(between the search's cells, then by two robots' scans)."""
PIN_REACH_M = 10.0
"""Where a robot is seen, its frame's walls within this of it are matched against the
seeing frame's map: about what both robots' LiDARs (8 m) saw where they met. All of an
office floor's walls (IPA office_e, 60 m across) made each search of many seconds."""
PIN_HALF_SIZE_M = 0.5
"""A robot seen as a small object stands within this (per axis) of where the search puts
it: the object's centre is guessed one radius behind its returns, and the seen robot's
pose and the scan are a cycle apart at most."""
MERGED_START_SIGMAS = np.array([0.1, 0.1, 0.02])
"""``[x, y, theta]`` sigmas (m, rad) of a start a merge placed. The merge fits the two
maps where they overlap, after the merged robot drifted on its own; a start held as
firmly as a known one keeps that drift in its early trajectory. Held at 0.3 m and 5°,
wrong constraints turned merged robots' paths by up to 0.63 rad (IPA office_f). The
start is not where the merge measured anything, though: held there, the merge's heading
error is carried into the frame it joins (office_f's first merge, 35 mrad off, turned
the host robot's path by 20 mrad)."""
CATCH_UP_IN_CYCLE = 10
"""A merged frame whose server is at most this many cycles behind is caught up in the
control cycle that takes it in; further behind, in the merge lane first."""
MERGE_LANE = "merges"
"""The jobs' lane of the merge looks (:mod:`acslam.pipeline.jobs`): in a served run the
searches, and the catch-up of a merged frame's server on every message its robots sent
(seconds, growing with the run), go on beside the control loop; the merged frame is taken
in at the first cycle after, caught up on the cycles in between."""
SAME_CANDIDATE_M = 0.3
SAME_CANDIDATE_RAD = math.radians(5.0)
"""Two looks found the same candidate when their poses are this close."""


def frame_name(base_robot_id: int) -> str:
    """A frame is named after the robot at its origin."""
    return f"robot_{base_robot_id}/map"


def frame_grid_spec(extent: GridSpec) -> GridSpec:
    """A square grid about a frame's origin that holds ``extent`` whatever pose in it the
    origin has: half as wide as ``extent``'s diagonal, on each side."""
    half_cells = math.ceil(math.hypot(extent.width_m, extent.height_m) / extent.resolution_m)
    corner_m = -half_cells * extent.resolution_m  # the origin on a cell corner
    return GridSpec(corner_m, corner_m, extent.resolution_m, 2 * half_cells, 2 * half_cells)


@dataclass(frozen=True)
class FrameView:
    """One frame as of a snapshot: its robots (global ids; the first stands at its
    origin), their start poses in it, its grid and its server's snapshot (which numbers
    the robots ``0..k-1`` in the order of ``robot_ids``)."""

    name: str
    robot_ids: tuple[int, ...]
    starts: np.ndarray
    spec: GridSpec
    snapshot: Snapshot


@dataclass(frozen=True)
class FrameMerge:
    """A merge: at ``time_s``, the frame of robots ``merged_robot_ids`` was found at
    ``decision.pose`` in the frame of robots ``into_robot_ids`` (each frame's first robot
    stands at its origin), when those robots stood at ``merged_poses`` in their frame (at
    ``poses_time_s``: the evidence's time, earlier than ``time_s`` where the look ran
    beside the control loop). The maps before (cropped to what each knew) and the merged
    map after are kept for the report. ``into_trajectories`` and ``merged_trajectories``
    (per robot of either frame: keyframe stamps and poses in its frame) are the frames'
    estimates when the merge was taken in: where a scorer finds how each frame had
    drifted at the place of the merge."""

    time_s: float
    into_robot_ids: tuple[int, ...]
    merged_robot_ids: tuple[int, ...]
    decision: MergeDecision
    merged_poses: np.ndarray
    poses_time_s: float
    before: tuple[tuple[np.ndarray, GridSpec], tuple[np.ndarray, GridSpec]]
    after: tuple[np.ndarray, GridSpec]
    into_trajectories: tuple[tuple[np.ndarray, np.ndarray], ...]
    merged_trajectories: tuple[tuple[np.ndarray, np.ndarray], ...]


@dataclass
class _Frame:
    """A frame's robots, their starts in it, its server, and every message its robots
    sent, cycle by cycle (robot ids as sent), for the server a merge builds."""

    robot_ids: tuple[int, ...]
    starts: np.ndarray
    placed: frozenset[int]
    server: Server
    history: list[tuple[float, list[RobotMessage]]] = field(default_factory=list)

    @property
    def name(self) -> str:
        return frame_name(self.robot_ids[0])

    def to_local(self, message: RobotMessage) -> RobotMessage:
        return replace(message, robot_id=self.robot_ids.index(message.robot_id))


def _known_part(snapshot: Snapshot, spec: GridSpec) -> tuple[np.ndarray, GridSpec]:
    """The frame's map cropped to its known cells (a copy)."""
    values = snapshot.map.occupancy_values()
    window = known_window(values, spec, 0.0)
    return np.array(window.crop(values)), window.spec


def _search_grid(known: tuple[np.ndarray, GridSpec]) -> tuple[np.ndarray, GridSpec]:
    """The map as the merge search reads it: at ``SEARCH_RESOLUTION_M`` or its own cells,
    whichever is coarser."""
    values, spec = known
    factor = max(1, round(SEARCH_RESOLUTION_M / spec.resolution_m))
    return coarsened(values, spec, factor) if factor > 1 else known


class _TeamLocalization:
    """The trajectories of all robots, each in its frame, and every frame's landmarks."""

    def __init__(self, frames: Sequence[FrameView]) -> None:
        self._frames = frames

    def trajectory(self, robot_id: int) -> tuple[np.ndarray, np.ndarray]:
        for frame in self._frames:
            if robot_id in frame.robot_ids:
                local = frame.robot_ids.index(robot_id)
                return frame.snapshot.localization.trajectory(local)
        raise KeyError(robot_id)

    def landmarks(self) -> np.ndarray:
        return np.vstack([f.snapshot.localization.landmarks() for f in self._frames])


class FramedServer:
    """The server for a team with unknown relative starts: a frame per robot, merged as
    the data allows (see the module's docstring)."""

    def __init__(
        self,
        config: ScenarioConfig,
        robot_count: int,
        extent: GridSpec,
        jobs: Callable[[], Jobs] = InlineJobs,
    ) -> None:
        """``extent``: the deployment's map extent (only its size is used: the frames'
        grids are squares about their origins that hold it). ``jobs`` makes the jobs of
        each frame's server (:class:`Server`'s ``jobs``) and of the merge looks
        (``MERGE_LANE``)."""
        self._config = config
        self._make_jobs = jobs
        self._jobs = jobs()
        self._look: Future[_Found | None] | None = None
        self._spec = frame_grid_spec(extent)
        self._frames = [
            self._new_frame((i,), np.zeros((1, 3)), frozenset()) for i in range(robot_count)
        ]
        self._robot_count = robot_count
        self._lost: dict[int, float] = {}
        self._merges: list[FrameMerge] = []
        self._merge_tries = Periodic(config.algorithms.server.merge_period_s)
        # Per pair of frames, the candidate merge awaiting confirmation with where (in the
        # first frame) robots were seen where it puts them.
        self._candidates: dict[tuple[str, str], tuple[MergeDecision, list[np.ndarray]]] = {}
        self._snapshots = [frame.server.snapshot(0.0) for frame in self._frames]
        self._timings_s: dict[str, float] = {}

    def _new_frame(
        self, robot_ids: tuple[int, ...], starts: np.ndarray, placed: frozenset[int]
    ) -> _Frame:
        """``placed``: the robots whose starts a merge placed (held as loosely as
        ``MERGED_START_SIGMAS``)."""
        sigmas = {robot_ids.index(r): MERGED_START_SIGMAS for r in placed}
        server = Server(
            self._config, starts, self._spec, self._make_jobs(),
            scan_obstacles=True, start_sigmas=sigmas,
        )  # fmt: skip
        return _Frame(robot_ids, starts, placed, server)

    def _frame_of(self, robot_id: int) -> _Frame:
        return next(f for f in self._frames if robot_id in f.robot_ids)

    def mark_lost(self, robot_id: int, now_s: float) -> None:
        """See :meth:`Server.mark_lost`."""
        self._lost.setdefault(robot_id, now_s)
        frame = self._frame_of(robot_id)
        frame.server.mark_lost(frame.robot_ids.index(robot_id), now_s)

    def close(self) -> None:
        self._jobs.close()
        for frame in self._frames:
            frame.server.close()

    def step(self, messages: Iterable[RobotMessage], now_s: float) -> Snapshot:
        """Take a merge the last look found, look again when due, then run each frame's
        server on its robots' messages."""
        self._timings_s = {}
        start = time.perf_counter()
        # The merge stage: taking the evidence and taking a merge in, and in process the
        # look too (its lane runs it when scheduled); in a served run the look runs beside.
        merge_start = time.perf_counter()
        looked = self._look is None and self._merge_tries.due(now_s)
        if looked:
            evidence = [self._evidence(i) for i in range(len(self._frames))]
            look = partial(self._look_for_merge, evidence, now_s)
            self._look = self._jobs.submit(MERGE_LANE, look)
        if self._look is not None and self._look.done():
            looked = True
            found = self._look.result()
            self._look = None
            if found is not None:
                self._take_in(found, now_s)
        if looked:
            self._timings_s["merge"] = time.perf_counter() - merge_start
        by_frame: dict[str, list[RobotMessage]] = {f.name: [] for f in self._frames}
        for message in messages:
            by_frame[self._frame_of(message.robot_id).name].append(message)
        self._snapshots = []
        for frame in self._frames:
            received = by_frame[frame.name]
            if len(self._frames) > 1:  # a frame alone will never be merged again
                frame.history.append((now_s, received))
            snapshot = frame.server.step([frame.to_local(m) for m in received], now_s)
            self._snapshots.append(snapshot)
            for stage, seconds in snapshot.timings_s.items():
                self._timings_s[stage] = self._timings_s.get(stage, 0.0) + seconds
        self._timings_s["cycle"] = time.perf_counter() - start
        return self.snapshot(now_s)

    # ------------------------------------------------------------------ merging

    def _evidence(self, index: int) -> _Evidence:
        """What a merge look reads of frame ``index``, taken in the control cycle."""
        frame, snapshot = self._frames[index], self._snapshots[index]
        return _Evidence(
            frame,
            _known_part(snapshot, self._spec),
            frame.server.moving_objects_m(),
            np.array(snapshot.poses),
            tuple(frame.server.latest_scan(i) for i in range(len(frame.robot_ids))),
            tuple(frame.history),
        )

    def _look_for_merge(self, evidence: list[_Evidence], now_s: float) -> _Found | None:
        """Look at every pair of frames: where a robot of one sees a small object that a
        robot of the other could be, search there (:func:`_pinned_search`); weigh the
        match found, or else the pair's candidate. The first merge confirmed ends the
        look (the frames change; the rest wait for the next), with its server built."""
        for a in range(len(evidence)):
            for b in range(a + 1, len(evidence)):
                pair = (evidence[a].frame.name, evidence[b].frame.name)
                decision = _pinned_search(evidence[a], evidence[b])
                if decision is None and pair in self._candidates:
                    decision = self._candidates[pair][0]
                if decision is not None and self._weigh(pair, evidence[a], evidence[b], decision):
                    return self._merged(a, b, evidence[a], evidence[b], decision, now_s)
        return None

    def _weigh(
        self, pair: tuple[str, str], a: _Evidence, b: _Evidence, decision: MergeDecision
    ) -> bool:
        """Add what the robots' scans now say of ``decision`` to the pair's candidate:
        a scan through a place it puts a robot refutes it; robots seen where it puts them
        at places ``SIGHTINGS_APART_M`` apart confirm it (a pillar or a door frame can
        pass for a robot once, but does not move with it). True once confirmed."""
        seen, missed = _sightings(a, b, decision, self._config.robots.radius_m)
        if missed:
            self._candidates.pop(pair, None)
            return False
        kept = self._candidates.get(pair)
        sighted = kept[1] if kept is not None and _same_pose(kept[0], decision) else []
        sighted = sighted + seen
        self._candidates[pair] = (decision, sighted)
        return _spread_m(sighted) >= SIGHTINGS_APART_M

    def _merged(
        self,
        a: int,
        b: int,
        first: _Evidence,
        second: _Evidence,
        decision: MergeDecision,
        now_s: float,
    ) -> _Found:
        """One server for frames ``a`` and ``b`` in ``a``'s frame, at the merge's refined
        pose, fed every message their robots sent up to the evidence (taken at ``now_s``)."""
        if decision.resolution_m > first.known[1].resolution_m:
            decision = on_finer_cells(*first.known, *second.known, decision)
        pose = decision.pose
        assert pose is not None
        starts = {r: s for r, s in zip(first.frame.robot_ids, first.frame.starts, strict=True)}
        for robot_id, start in zip(second.frame.robot_ids, second.frame.starts, strict=True):
            starts[robot_id] = compose(pose, start)
        robot_ids = tuple(sorted(starts))
        placed = first.frame.placed | set(second.frame.robot_ids)
        merged = self._new_frame(robot_ids, np.array([starts[r] for r in robot_ids]), placed)
        _catch_up(merged, first.history, second.history)
        before = (first.known, second.known)
        return _Found(a, b, decision, second.poses, now_s, before, merged)

    def _take_in(self, found: _Found, now_s: float) -> None:
        """Put the merged frame in place of the two it merges, caught up on what their
        robots sent while it was built. More than ``CATCH_UP_IN_CYCLE`` cycles of that
        are caught up in the merge lane first, and the frame taken in when that is done."""
        first, second = self._frames[found.a], self._frames[found.b]
        merged = found.merged
        done = len(merged.history)
        if len(first.history) - done > CATCH_UP_IN_CYCLE:
            behind = (tuple(first.history[done:]), tuple(second.history[done:]))
            self._look = self._jobs.submit(MERGE_LANE, partial(_caught_up, found, *behind))
            return
        _catch_up(merged, first.history[done:], second.history[done:])
        for robot_id, lost_s in self._lost.items():
            if robot_id in merged.robot_ids:
                merged.server.mark_lost(merged.robot_ids.index(robot_id), lost_s)
        into_trajectories, merged_trajectories = (
            tuple(self._snapshots[k].localization.trajectory(i) for i in range(len(f.robot_ids)))
            for k, f in ((found.a, first), (found.b, second))
        )
        first.server.close()
        second.server.close()
        self._frames[found.a] = merged
        del self._frames[found.b]
        # Frame a keeps its name and coordinates; what was found about frame b is gone.
        for pair in [p for p in self._candidates if second.name in p]:
            del self._candidates[pair]
        if len(self._frames) == 1:
            merged.history.clear()
        self._snapshots[found.a] = merged.server.snapshot(now_s)
        del self._snapshots[found.b]
        after = _known_part(self._snapshots[found.a], self._spec)
        self._merges.append(
            FrameMerge(
                now_s, first.robot_ids, second.robot_ids, found.decision, found.merged_poses,
                found.poses_time_s, found.before, after, into_trajectories, merged_trajectories,
            )
        )  # fmt: skip

    # ------------------------------------------------------------------ snapshot

    def snapshot(self, now_s: float) -> Snapshot:
        """The team's state: per robot, its pose, goal and path in its frame
        (``robot_frames``); the map, costmap and frontiers of robot 0's frame; every
        frame in ``frames``, every merge so far in ``merges``."""
        n = self._robot_count
        views = tuple(
            FrameView(f.name, f.robot_ids, f.starts, self._spec, s)
            for f, s in zip(self._frames, self._snapshots, strict=True)
        )
        poses = np.zeros((n, 3))
        robot_frames = [""] * n
        goals: list[np.ndarray | None] = [None] * n
        paths: list[np.ndarray | None] = [None] * n
        idle: list[float | None] = [None] * n
        stuck = [0] * n
        commands = []
        for view in views:
            snap = view.snapshot
            for local, robot_id in enumerate(view.robot_ids):
                poses[robot_id] = snap.poses[local]
                robot_frames[robot_id] = view.name
                goals[robot_id], paths[robot_id] = snap.goals_m[local], snap.paths_m[local]
                idle[robot_id], stuck[robot_id] = snap.idle_since_s[local], snap.stuck_events[local]
            commands += [replace(c, robot_id=view.robot_ids[c.robot_id]) for c in snap.commands]
        poses.flags.writeable = False
        home = next(v.snapshot for v in views if 0 in v.robot_ids)
        explored = [v.snapshot.explored_s for v in views]
        return Snapshot(
            time_s=now_s,
            commands=_in_robot_order(commands),
            poses=poses,
            robot_frames=tuple(robot_frames),
            map=home.map,
            localization=LocalizationView(_TeamLocalization(views)),
            costmap=home.costmap,
            window=home.window,
            frontier_cells=home.frontier_cells,
            clusters=home.clusters,
            goals_m=tuple(goals),
            paths_m=tuple(paths),
            idle_since_s=tuple(idle),
            stuck_events=tuple(stuck),
            lost=MappingProxyType(dict(self._lost)),
            finished=all(v.snapshot.finished for v in views),
            explored_s=None if None in explored else max(e for e in explored if e is not None),
            timings_s=MappingProxyType(dict(self._timings_s)),
            frames=views,
            merges=tuple(self._merges),
        )


@dataclass(frozen=True)
class _Evidence:
    """What a merge look reads of one frame, taken in a control cycle: the frame (its
    robots and starts), its map's known part, the small objects its robots' latest scans
    show (:meth:`Server.moving_objects_m`), its robots' poses and latest scans (sensor pose
    and scan, None before the first), and the messages its robots sent so far."""

    frame: _Frame
    known: tuple[np.ndarray, GridSpec]
    seen_m: np.ndarray
    poses: np.ndarray
    scans: tuple[tuple[np.ndarray, LidarScan] | None, ...]
    history: tuple[tuple[float, list[RobotMessage]], ...]


@dataclass(frozen=True)
class _Found:
    """A confirmed merge of frame ``b`` into frame ``a`` (indices when its evidence was
    taken; frames change only when a merge is taken in): the decision, the merged robots'
    poses then and when, both maps then, and the merged frame's server, caught up to
    then."""

    a: int
    b: int
    decision: MergeDecision
    merged_poses: np.ndarray
    poses_time_s: float
    before: tuple[tuple[np.ndarray, GridSpec], tuple[np.ndarray, GridSpec]]
    merged: _Frame


def _catch_up(
    merged: _Frame,
    history_a: Sequence[tuple[float, list[RobotMessage]]],
    history_b: Sequence[tuple[float, list[RobotMessage]]],
) -> None:
    """Feed the merged frame's server, cycle by cycle, what the two frames' robots sent."""
    for (time_s, sent_a), (_, sent_b) in zip(history_a, history_b, strict=True):
        received = sent_a + sent_b
        merged.history.append((time_s, received))
        merged.server.catch_up([merged.to_local(m) for m in received], time_s)
    merged.server.caught_up()


def _caught_up(
    found: _Found,
    history_a: Sequence[tuple[float, list[RobotMessage]]],
    history_b: Sequence[tuple[float, list[RobotMessage]]],
) -> _Found:
    """The found merge, its server fed what the frames' robots sent since it was built."""
    _catch_up(found.merged, history_a, history_b)
    return found


def _pinned_search(a: _Evidence, b: _Evidence) -> MergeDecision | None:
    """The best accepted match of frame ``b``'s map in frame ``a``'s among the poses that
    put a robot of one frame where a robot of the other sees a small object (within
    ``PIN_HALF_SIZE_M``, at every heading); None if no sighting gives one."""
    pins = [
        Pin(xy, pose[:2], PIN_HALF_SIZE_M, PIN_REACH_M) for xy in a.seen_m for pose in b.poses
    ] + [Pin(pose[:2], xy, PIN_HALF_SIZE_M, PIN_REACH_M) for xy in b.seen_m for pose in a.poses]
    if not pins:
        return None
    grid_a, grid_b = _search_grid(a.known), _search_grid(b.known)
    decisions = [find_merge(*grid_a, *grid_b, pin=pin) for pin in pins]
    accepted = [d for d in decisions if d.accepted]
    return max(accepted, key=lambda d: d.score) if accepted else None


def _sightings(
    a: _Evidence, b: _Evidence, decision: MergeDecision, radius_m: float
) -> tuple[list[np.ndarray], int]:
    """Where (in frame ``a``) the two frames' latest scans show the other frame's robots
    at the places the match puts them, and how many of those places the scans look
    through."""
    assert decision.pose is not None
    pose_b_in_a = decision.pose
    pose_a_in_b = between(pose_b_in_a, np.zeros(3))
    seen: list[np.ndarray] = []
    missed = 0
    for viewers, targets, placed, to_a in (
        (a, b, pose_b_in_a, np.zeros(3)),
        (b, a, pose_a_in_b, pose_b_in_a),
    ):
        target_xy = transform_points(placed, targets.poses[:, :2])
        for latest in viewers.scans:
            if latest is None:
                continue
            for xy in target_xy:
                vote = sighting(*latest, xy, radius_m)
                missed += vote is False
                if vote:
                    seen.append(transform_points(to_a, xy[None])[0])
    return seen, missed


SIGHTINGS_APART_M = 0.5
"""A candidate merges once robots were seen where it puts them at places this far apart."""
SIGHTING_TOLERANCE_M = 0.15
"""How far a robot may stand from where a match puts it: the match's error at the robot
and the time between its pose and the scan."""


def sighting_reach_m(range_max_m: float, radius_m: float) -> float:
    """How far a robot of ``radius_m`` can be seen by a LiDAR of ``range_max_m``: its near
    side must be in range, with beams beside it reaching farther."""
    return range_max_m - radius_m


def sighting(
    viewer_pose: np.ndarray,
    scan: LidarScan,
    target_xy: np.ndarray,
    radius_m: float,
    tolerance_m: float = SIGHTING_TOLERANCE_M,
) -> bool | None:
    """Whether ``scan``, taken at ``viewer_pose``, shows a robot of ``radius_m`` at
    ``target_xy``: True when beams end on it and beams beside it reach farther (a small
    object, not a wall), False when the beams toward it all run past it, None when the
    scan cannot tell (out of range, hidden behind something nearer, a wall there)."""
    offset = np.asarray(target_xy) - viewer_pose[:2]
    distance_m = float(np.hypot(*offset))
    if distance_m <= radius_m + tolerance_m or distance_m >= sighting_reach_m(
        scan.range_max_m, radius_m
    ):
        return None
    bearings = wrap_angles(scan.angles + viewer_pose[2] - math.atan2(offset[1], offset[0]))
    spacing = float(np.median(np.abs(np.diff(scan.angles)))) if len(scan.angles) > 1 else 0.0
    half_width = math.asin(min(1.0, radius_m / distance_m)) + 0.5 * spacing
    toward = np.abs(bearings) <= half_width
    if np.count_nonzero(toward) < 2:
        return None
    ranges = scan.ranges[toward]
    if np.all(ranges > distance_m + tolerance_m):
        return False
    ends_on_it = (ranges >= distance_m - radius_m - tolerance_m) & (
        ranges <= distance_m + tolerance_m
    )
    if not ends_on_it.any():
        return None
    beside = (np.abs(bearings) > half_width) & (np.abs(bearings) <= half_width + 3 * spacing)
    left, right = beside & (bearings > 0), beside & (bearings < 0)
    farther = scan.ranges > distance_m + radius_m
    return bool((left & farther).any() and (right & farther).any()) or None


def _same_pose(kept: MergeDecision, decision: MergeDecision) -> bool:
    """Two looks found the same candidate (``SAME_CANDIDATE_M``, ``SAME_CANDIDATE_RAD``)."""
    assert kept.pose is not None and decision.pose is not None
    gap = np.asarray(decision.pose) - kept.pose
    return bool(
        np.hypot(gap[0], gap[1]) < SAME_CANDIDATE_M and abs(wrap_angle(gap[2])) < SAME_CANDIDATE_RAD
    )


def _spread_m(points: list[np.ndarray]) -> float:
    """The largest distance between two of the points (0 for fewer than two)."""
    if len(points) < 2:
        return 0.0
    return float(pdist(np.array(points)).max())


def _in_robot_order(commands: list[VelocityCommand]) -> tuple[VelocityCommand, ...]:
    return tuple(sorted(commands, key=lambda c: c.robot_id))
