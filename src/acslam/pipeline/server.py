"""The centralized server: the stages of thesis Fig. 4.2 on a schedule.

Every control period: ingest robot messages -> localizer (SLAM) -> mapper (following pose
corrections); at the map-update period: costmap -> frontier detector -> clusterer, and half
a period later the localizer's loop-closure search; at the replanning period, or when a
robot reached or lost its goal: allocator -> global planner; then the local planner for
the whole team -> velocity commands. Once explored, the scenario may keep the robots
driving loops through the map (``patrol_s``) instead of allocating frontiers. Each stage
is the plugin the scenario names (:mod:`acslam.pipeline.registry`); what the step decided
leaves the server only as a :class:`~acslam.pipeline.snapshot.Snapshot`.

The server sees only :mod:`acslam.messages` and the map's extent (a deployment parameter,
like the thesis's fixed 40 m x 40 m grid); it never touches simulator ground truth. The
costmap and the planners work on the known area's window of the grid
(:func:`~acslam.mapping.costmap.known_window`).

Mapping, the map update, the decisions (allocation and global plans) and the localizer's
loop-closure matching are jobs (:mod:`acslam.pipeline.jobs`): in-process runs do them in
the cycle that scheduled them; served runs do them beside the control loop, which keeps
localizing and sending the local planner's commands meanwhile. A job reads what was handed
to it when it was scheduled and the stages only its lane's jobs touch, one job at a time in
order; its result changes the server's state only when the control cycle takes it. Readers
of the map outside the server (a live view, the run's explored-area samples) may then see a
scan half added."""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Future
from contextlib import contextmanager
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from acslam import threads
from acslam.config import ScenarioConfig
from acslam.errors import NoPathError
from acslam.exploration.clustering import FrontierCluster
from acslam.exploration.frontiers import away_from_robots
from acslam.exploration.patrol import Patrol
from acslam.geometry import beam_ends
from acslam.grid import FREE, GridSpec, Window
from acslam.mapping.costmap import Costmap, CostmapUpdater, known_window
from acslam.messages import LidarScan, RobotMessage, VelocityCommand
from acslam.pipeline.jobs import InlineJobs, Jobs
from acslam.pipeline.perception import KeptScan, Perception
from acslam.pipeline.registry import (
    ALLOCATORS,
    CLUSTERERS,
    FRONTIER_DETECTORS,
    GLOBAL_PLANNERS,
    LOCAL_PLANNERS,
    LOCALIZERS,
    MAPPERS,
)
from acslam.pipeline.snapshot import LocalizationView, MapView, Snapshot
from acslam.planning.astar import lookahead_point, remaining_length_m
from acslam.planning.field import DistanceField, ObstacleField, RobotState
from acslam.planning.recovery import Recovery, penalize
from acslam.schedule import Periodic, is_due

TEAM_FRAME = "map"
UNEXPLAINED_M = 0.1
"""A scan return this far from the map's obstacles is one the map does not explain."""
MOVING_OBJECT_RETURNS = 2
"""Returns in the map's free space that show something moved in. A robot 0.21 m across
gives 2 or more at 1 degree within 6 m, 3 or more only within 4 m. With 3, two robots of
IPA office_e (random starts, seed 1) that passed each other 5.6-7.6 m apart at 576, 600
and 697 s merged only at 727 s, 4 m apart; with 2, at 698 s. One return is no object
(noise, a wall's edge)."""
SMALL_OBJECT_SLACK_M = 0.15
"""How much wider than a robot a run of unexplained returns may be and still be one: the
scan's noise and the viewer's motion during the sweep."""
MAP_LANE = "map"
"""Jobs of the mapper, the frontier detector and the clusterer (see acslam.pipeline.jobs)."""
DECISION_LANE = "decisions"
"""Jobs of the allocator and the global planner."""


@dataclass
class RobotTask:
    """What the server has decided for one robot."""

    recovery: Recovery
    cluster: FrontierCluster | None = None
    path_m: np.ndarray | None = None
    velocity: tuple[float, float] = (0.0, 0.0)
    idle_since_s: float | None = None


@dataclass(frozen=True)
class _MapProducts:
    """What the map update scheduled at ``time_s`` made of the grid: the known window,
    its costmap and the local planners' clearance field on it, the frontier cells (of the
    whole grid) and their clusters (of the window)."""

    time_s: float
    values: np.ndarray
    window: Window
    costmap: Costmap
    field: DistanceField
    frontier_cells: np.ndarray
    clusters: list[FrontierCluster]
    timings_s: dict[str, float]


@dataclass(frozen=True)
class _TaskState:
    """What the decisions read of a robot's task, copied when they were scheduled."""

    cluster: FrontierCluster | None
    has_path: bool
    idle_since_s: float | None
    traps_xy_m: tuple[np.ndarray, ...]


@dataclass(frozen=True)
class _Plan:
    """A robot's goal and global path from the decisions (both None: it has neither)."""

    cluster: FrontierCluster | None
    path_m: np.ndarray | None
    new_goal: bool
    remaining_m: float


@dataclass(frozen=True)
class _Decisions:
    """The decisions' result: plans by robot, and whether the team is done exploring
    (with the patrol that follows, if any) or done patrolling."""

    plans: dict[int, _Plan]
    idle_since_s: dict[int, float | None]
    explored_s: float | None
    patrol: Patrol | None
    finished: bool
    timings_s: dict[str, float]


def costmap_reach_m(config: ScenarioConfig, spec: GridSpec) -> float:
    """How far the server's costmap measures distances: nothing reads one beyond the cost
    radius, the local planners' obstacle influence or the patrol's clearance; two cell
    diagonals more keep the planners' bilinear field exact wherever it is below their
    influence."""
    algorithms = config.algorithms
    return (
        max(
            algorithms.costmap.radius_m,
            algorithms.planning.obstacle_influence_m,
            2 * config.robots.radius_m,
        )
        + 2 * math.sqrt(2.0) * spec.resolution_m
    )


def small_objects_m(
    viewer_pose: np.ndarray, ends_m: np.ndarray, unexplained: np.ndarray, radius_m: float
) -> np.ndarray:
    """(K, 2) centres of the small objects one scan shows: runs of at least
    ``MOVING_OBJECT_RETURNS`` consecutive beams that end where the map does not explain,
    no wider than a robot (with ``SMALL_OBJECT_SLACK_M``). The beams end on the object's
    near side, so its centre is taken one radius behind their mean, along the view."""
    centres = []
    edges = np.diff(np.concatenate([[0], unexplained.astype(np.int8), [0]]))
    for first, end in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        run = ends_m[first:end]
        if len(run) < MOVING_OBJECT_RETURNS:
            continue
        if np.hypot(*np.ptp(run, axis=0)) > 2 * radius_m + SMALL_OBJECT_SLACK_M:
            continue
        mean = run.mean(axis=0)
        view = mean - viewer_pose[:2]
        centres.append(mean + radius_m * view / np.hypot(*view))
    return np.array(centres).reshape(-1, 2)


class Server:
    """Localizes, maps, explores and plans for the whole team from robot messages."""

    def __init__(
        self,
        config: ScenarioConfig,
        starts: np.ndarray,
        map_spec: GridSpec,
        jobs: Jobs | None = None,
        scan_obstacles: bool = False,
        start_sigmas: dict[int, np.ndarray] | None = None,
    ) -> None:
        """``jobs``: where mapping, the map update, the decisions and loop-closure
        matching run (in the cycle that schedules them unless given, see
        :mod:`acslam.pipeline.jobs`). ``scan_obstacles``: lay each robot's latest scan's
        returns that the map does not explain over the local planners' field, for a team
        that may meet robots it does not know (:mod:`acslam.pipeline.frames`).
        ``start_sigmas``: by robot, ``[x, y, theta]`` sigmas of a start known only as well
        as a merge of frames placed it (the localizer's ``start_sigmas``)."""
        self._config = config
        self._jobs: Jobs = InlineJobs() if jobs is None else jobs
        algorithms = config.algorithms
        self._robot_count = len(starts)
        self._map_spec = map_spec
        self._localizer = LOCALIZERS.create(
            algorithms.localizer,
            scan_matching=algorithms.scan_matching,
            starts={i: np.asarray(s) for i, s in enumerate(starts)},
            jobs=self._jobs,
            **({} if start_sigmas is None else {"start_sigmas": start_sigmas}),
        )
        reach_m = config.robots.radius_m + algorithms.server.robot_filter_margin_m
        self._perception = Perception(
            self._localizer,
            range(self._robot_count),
            reach_m,
            algorithms.server.map_update_period_s,
        )
        self._mapper = MAPPERS.create(algorithms.mapper, spec=map_spec)
        self._frontier_detector = FRONTIER_DETECTORS.create(
            algorithms.frontier_detector, spec=map_spec, mapping=algorithms.mapper
        )
        self._clusterer = CLUSTERERS.create(algorithms.clusterer)
        self._costmaps = CostmapUpdater(
            algorithms.costmap, config.robots.radius_m, costmap_reach_m(config, map_spec)
        )
        self._allocator = ALLOCATORS.create(algorithms.allocator)
        self._global_planner = GLOBAL_PLANNERS.create(algorithms.global_planner)
        self._local_planner = LOCAL_PLANNERS.create(
            algorithms.local_planner, planning=algorithms.planning, robots=config.robots
        )
        self._tasks = [RobotTask(Recovery(algorithms.planning)) for _ in range(self._robot_count)]
        self._timings_s: dict[str, float] = {}
        self._new_scan_cells: list[np.ndarray] = []
        self._corrected = False
        self._costmap: Costmap | None = None
        self._field: DistanceField | None = None
        self._window: Window | None = None
        self._values: np.ndarray | None = None
        self._frontier_cells = np.zeros((0, 2), dtype=np.int64)
        self._clusters: list[FrontierCluster] = []
        self._mapping_jobs: deque[Future[float]] = deque()
        self._map_job: Future[_MapProducts] | None = None
        self._map_time_s = -math.inf
        self._decision_job: Future[_Decisions] | None = None
        self._map_updates = Periodic(algorithms.server.map_update_period_s)
        self._next_replan_s = 0.0
        self._replan_now = True
        self._finished = False
        self._explored_s: float | None = None
        self._patrol: Patrol | None = None
        self._lost: dict[int, float] = {}
        self._scan_obstacles = scan_obstacles
        self._latest_scans: dict[int, tuple[np.ndarray, LidarScan]] = {}
        # While catching up with a history-free mapper: scans not yet mapped, by index,
        # each at the pose it would have been last moved to.
        self._held_scans: dict[int, tuple[KeptScan, np.ndarray]] | None = None

    def mark_lost(self, robot_id: int, now_s: float) -> None:
        """Give up on a robot that stopped answering (e.g. heartbeat timeout).

        Its frontier goes back to the pool at once, its planner state is dropped and it
        gets no more goals; the others plan around its last estimated pose, where it
        stands. Its map and trajectory so far stay.
        """
        if robot_id in self._lost:
            return
        self._lost[robot_id] = now_s
        task = self._tasks[robot_id]
        task.cluster, task.path_m, task.velocity = None, None, (0.0, 0.0)
        self._local_planner.reset(robot_id)
        self._replan_now = True

    # ------------------------------------------------------------------ schedule

    def step(self, messages: Iterable[RobotMessage], now_s: float) -> Snapshot:
        """Run one server cycle on the messages received since the last one."""
        self._timings_s = {}
        with self._timed("cycle"):
            commands = self._step(messages, now_s)
        return self.snapshot(now_s, commands)

    def snapshot(self, now_s: float, commands: Sequence[tuple[float, float]] = ()) -> Snapshot:
        """The state as of ``now_s``: what :meth:`step` returns, and before the first
        step the empty start (no map, no commands)."""
        poses = np.array([self._localizer.latest_pose(i) for i in range(self._robot_count)])
        poses.flags.writeable = False
        return Snapshot(
            time_s=now_s,
            commands=tuple(VelocityCommand(i, now_s, v, w) for i, (v, w) in enumerate(commands)),
            poses=poses,
            robot_frames=(TEAM_FRAME,) * self._robot_count,
            map=MapView(self._mapper.version, self._mapper),
            localization=LocalizationView(self._localizer),
            costmap=self._costmap,
            window=self._window,
            frontier_cells=self._frontier_cells,
            clusters=tuple(self._clusters),
            goals_m=tuple(t.cluster.target_m if t.cluster else None for t in self._tasks),
            paths_m=tuple(t.path_m for t in self._tasks),
            idle_since_s=tuple(t.idle_since_s for t in self._tasks),
            stuck_events=tuple(t.recovery.count for t in self._tasks),
            lost=MappingProxyType(dict(self._lost)),
            finished=self._finished,
            explored_s=self._explored_s,
            timings_s=MappingProxyType(self._timings_s),
        )

    @contextmanager
    def _timed(self, stage: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self._timings_s[stage] = time.perf_counter() - start

    def _step(self, messages: Iterable[RobotMessage], now_s: float) -> list[tuple[float, float]]:
        map_update_due = self._map_updates.due(now_s)
        with self._timed("slam"):
            scans = self._perception.localize(messages, now_s).scans
        if self._scan_obstacles:
            for kept in scans:
                pose = self._localizer.scan_pose(kept.index)
                self._latest_scans[kept.mappable.robot_id] = (pose, kept.mappable)
        self._integrate(scans)
        self._take_mapping()
        if map_update_due and self._map_job is None:
            self._map_job = self._jobs.submit(MAP_LANE, self._map_update(now_s))
        self._take_map_products()
        poses = np.array([self._localizer.latest_pose(i) for i in range(self._robot_count)])
        if (self._replan_now or is_due(now_s, self._next_replan_s)) and self._decision_job is None:
            if self._costmap is None:
                self._timings_s["allocation"] = 0.0
            else:
                self._decision_job = self._jobs.submit(DECISION_LANE, self._decisions(poses, now_s))
            self._next_replan_s = now_s + self._config.algorithms.planning.replan_period_s
            self._replan_now = False
        self._take_decisions(now_s)
        with self._timed("local_planning"):
            return self._local_plan(poses, now_s)

    def catch_up(self, messages: Iterable[RobotMessage], now_s: float) -> None:
        """Localize and map messages its robots sent before this server existed, in the
        cycles they arrived in, deciding nothing (a merged frame,
        :mod:`acslam.pipeline.frames`; its merge's time counts this work); then call
        :meth:`caught_up`.

        A history-free mapper (:class:`~acslam.pipeline.stages.Mapper`) gets each scan
        once, in :meth:`caught_up`, at the pose the corrections would have left it at:
        following every correction of a replay re-cast each scan many times (the
        dungeon's second merge, seed 2: 13.0 s against 9.0 s)."""
        if self._mapper.history_free and self._held_scans is None:
            self._held_scans = {}
        self._integrate(self._perception.localize(messages, now_s).scans)
        while self._mapping_jobs:
            self._mapping_jobs.popleft().result()

    def caught_up(self) -> None:
        """Map the scans :meth:`catch_up` held back."""
        held, self._held_scans = self._held_scans, None
        if held:
            added = list(held.values())
            self._jobs.submit(MAP_LANE, lambda: self._map_scans(added, [])).result()

    def latest_scan(self, robot_id: int) -> tuple[np.ndarray, LidarScan] | None:
        """The robot's latest scan (its mappable beams: known teammates' left out) and its
        sensor pose; kept only with ``scan_obstacles``."""
        return self._latest_scans.get(robot_id)

    def moving_objects_m(self) -> np.ndarray:
        """(K, 2) where the robots' latest scans show a small object standing where the map
        was seen free, away from its obstacles: a robot this server does not know, or
        anything else that moved in (``scan_obstacles`` only; see :func:`small_objects_m`)."""
        found = [np.zeros((0, 2))]
        if self._values is None or self._field is None:
            return found[0]
        for pose, scan in self._latest_scans.values():
            ends = beam_ends(pose, scan.angles, scan.ranges)
            returned = np.isfinite(scan.ranges) & (scan.ranges > 0)
            cells = self._map_spec.world_to_cell(np.where(returned[:, None], ends, pose[:2]))
            inside = returned & self._map_spec.contains(cells)
            unexplained = np.zeros(len(ends), dtype=bool)
            unexplained[inside] = self._values[cells[inside, 0], cells[inside, 1]] == FREE
            unexplained[inside] &= self._field.value(ends[inside]) > UNEXPLAINED_M
            found.append(small_objects_m(pose, ends, unexplained, self._config.robots.radius_m))
        return np.vstack(found)

    def _returns_within_reach(self) -> np.ndarray:
        """(K, 2) returns of the robots' latest scans within the local planners' reach."""
        planning = self._config.algorithms.planning
        reach_m = planning.horizon_s * self._config.robots.max_v_mps + planning.obstacle_influence_m
        returns = []
        for pose, scan in self._latest_scans.values():
            near = scan.ranges < reach_m
            returns.append(beam_ends(pose, scan.angles[near], scan.ranges[near]))
        return np.vstack(returns).reshape(-1, 2)

    def _unexplained_returns(self, field: DistanceField) -> np.ndarray:
        """(K, 2) returns of the robots' latest scans within the local planners' reach
        that stand off the map's obstacles: something the map update has not caught up
        with (returns on the map's walls change no clearance)."""
        points = self._returns_within_reach()
        return points[field.value(points) > UNEXPLAINED_M]

    def close(self) -> None:
        """End the run: wait for every job scheduled so far."""
        self._jobs.close()

    def _integrate(self, scans: list[KeptScan]) -> None:
        """Hand the mapper the new (mappable) scans at their keyframe-relative pose and
        the scans SLAM corrected at their new pose (a job)."""
        added = []
        for kept in scans:
            pose = self._localizer.scan_pose(kept.index)
            added.append((kept, pose))
            self._new_scan_cells.append(self._map_spec.world_to_cell(pose[:2])[0])
        moved = [
            (index, self._localizer.scan_pose(index)) for index in self._localizer.moved_scans()
        ]
        if moved:
            self._corrected = True
        held = self._held_scans
        if held is not None:  # catching up: map these in caught_up
            held.update((kept.index, (kept, pose)) for kept, pose in added)
            for index, pose in moved:
                if index in held:
                    held[index] = (held[index][0], pose)
            added, moved = [], [(index, pose) for index, pose in moved if index not in held]
        if added or moved:
            self._mapping_jobs.append(
                self._jobs.submit(MAP_LANE, lambda: self._map_scans(added, moved))
            )

    def _map_scans(
        self, added: list[tuple[KeptScan, np.ndarray]], moved: list[tuple[int, np.ndarray]]
    ) -> float:
        """Add and move scans in the mapper (a job; the mapper is touched by jobs only,
        one at a time in order). Returns its wall seconds."""
        start = time.perf_counter()
        for kept, pose in added:
            scan = kept.mappable
            self._mapper.add_scan(
                scan.robot_id, kept.index, scan.ranges, scan.angles, pose, scan.range_max_m
            )
        for index, pose in moved:
            self._mapper.move_scan(index, pose)
        return time.perf_counter() - start

    def _take_mapping(self) -> None:
        """The mapper's work that ended since the last cycle, as this cycle's mapping."""
        seconds = 0.0
        while self._mapping_jobs and self._mapping_jobs[0].done():
            seconds += self._mapping_jobs.popleft().result()
        self._timings_s["mapping"] = seconds

    def _map_update(self, now_s: float) -> Callable[[], _MapProducts]:
        """The map update's job, on the grid as the mapping jobs before it leave it, and
        the scans added since the last one (all of the map, after a correction)."""
        robot_cells = self._map_spec.world_to_cell(
            np.array([self._localizer.latest_pose(i)[:2] for i in range(self._robot_count)])
        )
        scan_cells = None if self._corrected else np.array(self._new_scan_cells).reshape(-1, 2)
        self._new_scan_cells.clear()
        self._corrected = False
        return lambda: self._map_products(now_s, robot_cells, scan_cells)

    def _map_products(
        self, now_s: float, robot_cells: np.ndarray, scan_cells: np.ndarray | None
    ) -> _MapProducts:
        """Costmap of the known window, frontiers, clusters (a job: reads only its
        arguments and the stages jobs alone use)."""
        timings_s: dict[str, float] = {}
        start = time.perf_counter()
        values = self._mapper.occupancy_values()
        server = self._config.algorithms.server
        window = known_window(values, self._map_spec, server.window_margin_m)
        costmap = self._costmaps.update(window.crop(values), window)
        # The distance field is to cell centres, walls are cell squares: half a cell
        # diagonal less makes the planners' clearance a lower bound of the truth.
        field = DistanceField(
            np.maximum(costmap.distance_m - window.spec.resolution_m / math.sqrt(2.0), 0.0),
            window.spec,
        )
        timings_s["costmap"] = time.perf_counter() - start
        start = time.perf_counter()
        frontier_cells = self._frontier_detector.update(values, robot_cells, scan_cells)
        # A robot's blind disc (its body, its LiDAR's minimum range) and the cell ring
        # around it: no frontier a robot could explore by going there.
        blind_m = max(self._config.robots.radius_m, self._config.sensors.lidar.range_min_m)
        reach_m = blind_m + 1.5 * self._map_spec.resolution_m  # and the free cells on its rim
        explorable = away_from_robots(frontier_cells, robot_cells, self._map_spec, reach_m)
        clusters = self._clusterer.cluster(
            window.to_local(explorable), window.crop(values), window.spec, costmap
        )
        timings_s["frontiers"] = time.perf_counter() - start
        return _MapProducts(
            now_s, values, window, costmap, field, frontier_cells, clusters, timings_s
        )

    def _take_map_products(self) -> None:
        job = self._map_job
        if job is None or not job.done():
            return
        self._map_job = None
        products = job.result()
        self._map_time_s = products.time_s
        self._values, self._window = products.values, products.window
        self._costmap, self._field = products.costmap, products.field
        self._clusters = products.clusters
        self._frontier_cells = products.frontier_cells
        self._timings_s.update(products.timings_s)

    # ------------------------------------------------------------------ decisions

    def _decisions(self, poses: np.ndarray, now_s: float) -> Callable[[], _Decisions]:
        """The decisions' job, on the map products and the tasks as of now."""
        costmap, window, values = self._costmap, self._window, self._values
        clusters = self._clusters
        assert costmap is not None and window is not None
        active = [i for i in range(self._robot_count) if i not in self._lost]
        tasks = {
            i: _TaskState(
                self._tasks[i].cluster,
                self._tasks[i].path_m is not None,
                self._tasks[i].idle_since_s,
                tuple(self._tasks[i].recovery.traps_xy_m),
            )
            for i in active
        }
        # Nothing left to explore is a finding only on a map that has begun and on
        # frontiers at most two map updates old (a served run's map lane may lag).
        period_s = self._config.algorithms.server.map_update_period_s
        can_finish = len(self._mapper) > 0 and now_s - self._map_time_s <= 2 * period_s
        return lambda: self._decide(
            poses, now_s, active, tasks, costmap, window, values, clusters, can_finish
        )

    def _decide(
        self, poses: np.ndarray, now_s: float, active: list[int], tasks: dict[int, _TaskState],
        costmap: Costmap, window: Window, values: np.ndarray | None,
        clusters: list[FrontierCluster], can_finish: bool,
    ) -> _Decisions:  # fmt: skip
        """Assign clusters and plan a global path to each; a robot with none goes idle.
        Once explored, drive the patrol's tour instead, if the scenario asks for one (a
        job: reads its arguments, its lane's stages and the patrol, which the control
        cycle replaces only when it takes this job's result)."""
        start = time.perf_counter()
        if self._patrol is not None:
            plans = self._patrol_plans(active, tasks, poses, costmap, window)
            finished = now_s - self._patrol.started_s >= self._config.algorithms.server.patrol_s
            idle = {i: None for i, plan in plans.items() if plan.path_m is not None}
            timings_s = {"allocation": time.perf_counter() - start}
            return _Decisions(plans, idle, None, self._patrol, finished, timings_s)
        robot_cells = window.spec.world_to_cell(poses[:, :2])
        robot_cells = np.clip(robot_cells, 0, np.array(window.spec.shape) - 1)
        current = [self._matching_cluster(tasks[i].cluster, clusters) for i in active]
        allocation = self._allocator.allocate(robot_cells[active], clusters, costmap, current)

        def plan(k: int) -> _Plan:
            i, choice = active[k], allocation.cluster_of_robot[k]
            target = None if choice is None else clusters[choice]
            return self._plan(tasks[i], target, poses[i, :2], costmap, window, choice != current[k])

        plans = dict(zip(active, threads.mapped(plan, len(active)), strict=True))
        idle: dict[int, float | None] = {}
        for i in active:
            if plans[i].path_m is not None:
                idle[i] = None
            else:
                idle[i] = now_s if tasks[i].idle_since_s is None else tasks[i].idle_since_s
        # Done once every robot has had nothing to do for a while (``can_finish``):
        # frontiers briefly vanish while a robot stands on the last one it was sent to.
        explored = (
            can_finish
            and bool(idle)
            and all(s is not None for s in idle.values())
            and now_s - max(s for s in idle.values() if s is not None)
            >= self._config.algorithms.server.finish_after_idle_s
        )
        explored_s, patrol, finished = None, None, False
        if explored:
            explored_s = now_s
            server = self._config.algorithms.server
            if server.patrol_s > 0 and values is not None:
                # Waypoints in the open, a robot radius clear of the lethal band.
                clear_m = 2 * self._config.robots.radius_m
                free = (window.crop(values) == FREE) & (costmap.distance_m >= clear_m)
                patrol = Patrol.over(
                    free, window.spec, server.patrol_spacing_m, poses[active[0]], now_s,
                    self._robot_count,
                )  # fmt: skip
            finished = patrol is None
        timings_s = {"allocation": time.perf_counter() - start}
        return _Decisions(plans, idle, explored_s, patrol, finished, timings_s)

    def _plan(
        self, task: _TaskState, target: FrontierCluster | None, xy_m: np.ndarray,
        costmap: Costmap, window: Window, changed: bool,
    ) -> _Plan:  # fmt: skip
        """The robot's global path to ``target``; without a target or a path to it the
        robot has neither."""
        path = None
        if target is not None:
            try:
                planning = self._config.algorithms.planning
                path = self._global_planner.plan(
                    penalize(costmap.cost, window.spec, task.traps_xy_m, planning),
                    costmap.lethal, window.spec, xy_m, target.target_m,
                )  # fmt: skip
            except NoPathError:
                path = None
        if path is None:
            return _Plan(None, None, changed, 0.0)
        path_m = np.vstack([xy_m, path])
        return _Plan(target, path_m, changed, remaining_length_m(path_m, xy_m))

    def _patrol_plans(
        self, active: list[int], tasks: dict[int, _TaskState], poses: np.ndarray,
        costmap: Costmap, window: Window,
    ) -> dict[int, _Plan]:  # fmt: skip
        """Each robot on along the tour."""
        assert self._patrol is not None
        plans = {}
        for i in active:
            old = tasks[i].cluster
            reached = old is not None and not tasks[i].has_path
            for waypoint in self._patrol.goals(i, reached):
                changed = old is None or not np.array_equal(old.target_m, waypoint.target_m)
                plans[i] = self._plan(tasks[i], waypoint, poses[i, :2], costmap, window, changed)
                if plans[i].path_m is not None:
                    break
        return plans

    def _take_decisions(self, now_s: float) -> None:
        """Give each robot its plan (a robot lost since they were scheduled gets none)."""
        job = self._decision_job
        if job is None or not job.done():
            return
        self._decision_job = None
        decisions = job.result()
        for i, plan in decisions.plans.items():
            if i in self._lost:
                continue
            task = self._tasks[i]
            task.cluster, task.path_m = plan.cluster, plan.path_m
            if plan.path_m is not None:
                task.recovery.replanned(now_s, plan.new_goal, plan.remaining_m)
        for i, idle_since_s in decisions.idle_since_s.items():
            if i not in self._lost:
                self._tasks[i].idle_since_s = idle_since_s
        if decisions.explored_s is not None:
            self._explored_s = decisions.explored_s
        self._patrol = decisions.patrol
        self._finished = decisions.finished
        self._timings_s.update(decisions.timings_s)

    def _matching_cluster(
        self, goal: FrontierCluster | None, clusters: list[FrontierCluster]
    ) -> int | None:
        """The cluster that continues a robot's ``goal``: its target is nearest the old
        target, within the goal tolerance plus the clusterer's linkage."""
        if goal is None or not clusters:
            return None
        targets = np.array([c.target_m for c in clusters])
        gaps = np.linalg.norm(targets - goal.target_m, axis=1)
        best = int(np.argmin(gaps))
        tolerance_m = self._config.algorithms.server.goal_tolerance_m + self._clusterer.linkage_m
        return best if gaps[best] <= tolerance_m else None

    def _local_plan(self, poses: np.ndarray, now_s: float) -> list[tuple[float, float]]:
        """(v, omega) for every robot: recovery overrides, else the local planner."""
        field = self._field
        if field is None:
            return [(0.0, 0.0)] * self._robot_count
        planning = self._config.algorithms.planning
        tolerance = self._config.algorithms.server.goal_tolerance_m
        reach_m = planning.horizon_s * self._config.robots.max_v_mps
        # Every robot takes part, so the others plan around it: a robot without a path
        # holds its position as its goal (and yields if another one comes close).
        states, goals, overrides = [], [], {}
        for i, task in enumerate(self._tasks):
            state = RobotState(*poses[i], *task.velocity)
            states.append(state)
            goals.append(state.xy_m)
            if task.path_m is None:
                continue
            remaining = remaining_length_m(task.path_m, state.xy_m)
            if remaining < tolerance:
                self._replan_now = True
                task.path_m = None
                continue
            step = task.recovery.step(now_s, state, remaining)
            if step.replan:
                self._replan_now = True
                self._local_planner.reset(i)
            if step.command is not None:
                overrides[i] = step.command
            goals[i] = lookahead_point(task.path_m, state.xy_m, reach_m)
        if self._scan_obstacles and self._latest_scans:
            field = ObstacleField(field, self._unexplained_returns(field))
        planned = self._local_planner.plan(states, goals, field)
        commands = [overrides.get(i, (float(v), float(w))) for i, (v, w) in enumerate(planned)]
        for i in self._lost:
            commands[i] = (0.0, 0.0)
        for i, task in enumerate(self._tasks):
            task.velocity = commands[i]
        return commands
