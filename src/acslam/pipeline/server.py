"""The centralized server: the stages of thesis Fig. 4.2 on a schedule.

Every control period: ingest robot messages -> localizer (SLAM) -> mapper (following pose
corrections); at the map-update period: costmap -> frontier detector -> clusterer; at the
replanning period, or when a robot reached or lost its goal: allocator -> global planner;
then the local planner for the whole team -> velocity commands. Once explored, the
scenario may keep the robots driving loops through the map (``patrol_s``) instead of
allocating frontiers. Each stage is the plugin the scenario names
(:mod:`acslam.pipeline.registry`); what the step decided leaves the server only as a
:class:`~acslam.pipeline.snapshot.Snapshot`.

The server sees only :mod:`acslam.messages` and the map's extent (a deployment parameter,
like the thesis's fixed 40 m x 40 m grid); it never touches simulator ground truth. The
costmap and the planners work on the known area's window of the grid
(:func:`~acslam.mapping.costmap.known_window`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from acslam.config import ScenarioConfig
from acslam.errors import NoPathError
from acslam.exploration.clustering import FrontierCluster
from acslam.exploration.patrol import Patrol
from acslam.grid import FREE, GridSpec, Window
from acslam.mapping.costmap import Costmap, compute_costmap, known_window
from acslam.messages import RobotMessage, VelocityCommand
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
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.recovery import Recovery

TEAM_FRAME = "map"


@dataclass
class RobotTask:
    """What the server has decided for one robot."""

    recovery: Recovery
    cluster: FrontierCluster | None = None
    path_m: np.ndarray | None = None
    velocity: tuple[float, float] = (0.0, 0.0)
    idle_since_s: float | None = None


class Server:
    """Localizes, maps, explores and plans for the whole team from robot messages."""

    def __init__(self, config: ScenarioConfig, starts: np.ndarray, map_spec: GridSpec) -> None:
        self._config = config
        algorithms = config.algorithms
        self._robot_count = len(starts)
        self._map_spec = map_spec
        self._localizer = LOCALIZERS.create(
            algorithms.localizer,
            scan_matching=algorithms.scan_matching,
            starts={i: np.asarray(s) for i, s in enumerate(starts)},
        )
        reach_m = config.robots.radius_m + algorithms.server.robot_filter_margin_m
        self._perception = Perception(self._localizer, range(self._robot_count), reach_m)
        self._mapper = MAPPERS.create(algorithms.mapper, spec=map_spec)
        self._frontier_detector = FRONTIER_DETECTORS.create(
            algorithms.frontier_detector, spec=map_spec, mapping=algorithms.mapper
        )
        self._clusterer = CLUSTERERS.create(algorithms.clusterer)
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
        self._window: Window | None = None
        self._values: np.ndarray | None = None
        self._frontier_cells = np.zeros((0, 2), dtype=np.int64)
        self._clusters: list[FrontierCluster] = []
        self._next_map_update_s = 0.0
        self._next_replan_s = 0.0
        self._replan_now = True
        self._finished = False
        self._explored_s: float | None = None
        self._patrol: Patrol | None = None
        self._lost: dict[int, float] = {}

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
        map_update_due = now_s >= self._next_map_update_s
        with self._timed("slam"):
            scans = self._perception.localize(messages, close_loops=map_update_due).scans
        with self._timed("mapping"):
            self._integrate(scans)
        if map_update_due:
            self._next_map_update_s = now_s + self._config.algorithms.server.map_update_period_s
            with self._timed("costmap"):
                self._update_costmap()
            with self._timed("frontiers"):
                self._update_frontiers()
        poses = np.array([self._localizer.latest_pose(i) for i in range(self._robot_count)])
        if self._replan_now or now_s >= self._next_replan_s:
            with self._timed("allocation"):
                self._allocate(poses, now_s)
            self._next_replan_s = now_s + self._config.algorithms.planning.replan_period_s
            self._replan_now = False
        with self._timed("local_planning"):
            return self._local_plan(poses, now_s)

    # ------------------------------------------------------------------ map

    def _integrate(self, scans: list[KeptScan]) -> None:
        """Add new (mappable) scans at their keyframe-relative pose; move scans SLAM
        corrected."""
        for kept in scans:
            pose = self._localizer.scan_pose(kept.index)
            scan = kept.mappable
            self._mapper.add_scan(
                scan.robot_id, kept.index, scan.ranges, scan.angles, pose, scan.range_max_m
            )
            self._new_scan_cells.append(self._map_spec.world_to_cell(pose[:2])[0])
        moved = self._localizer.moved_scans()
        if moved:
            for index in moved:
                self._mapper.move_scan(index, self._localizer.scan_pose(index))
            self._corrected = True

    def _update_costmap(self) -> None:
        values = self._mapper.occupancy_values()
        server = self._config.algorithms.server
        window = known_window(values, self._map_spec, server.window_margin_m)
        self._values = values
        self._window = window
        self._costmap = compute_costmap(
            window.crop(values),
            window.spec,
            self._config.algorithms.costmap,
            self._config.robots.radius_m,
        )

    def _update_frontiers(self) -> None:
        assert self._values is not None and self._window is not None and self._costmap is not None
        robot_cells = self._map_spec.world_to_cell(
            np.array([self._localizer.latest_pose(i)[:2] for i in range(self._robot_count)])
        )
        scan_cells = None if self._corrected else np.array(self._new_scan_cells).reshape(-1, 2)
        self._frontier_cells = self._frontier_detector.update(self._values, robot_cells, scan_cells)
        self._new_scan_cells.clear()
        self._corrected = False
        window = self._window
        self._clusters = self._clusterer.cluster(
            window.to_local(self._frontier_cells),
            window.crop(self._values),
            window.spec,
            self._costmap,
        )

    # ------------------------------------------------------------------ decisions

    def _allocate(self, poses: np.ndarray, now_s: float) -> None:
        """Assign clusters and plan a global path to each; a robot with none goes idle.
        Once explored, drive the patrol's tour instead, if the scenario asks for one."""
        costmap, window = self._costmap, self._window
        if costmap is None or window is None:
            return
        active = [i for i in range(self._robot_count) if i not in self._lost]
        if self._patrol is not None:
            self._drive_patrol(active, poses, now_s)
            return
        robot_cells = window.spec.world_to_cell(poses[:, :2])
        robot_cells = np.clip(robot_cells, 0, np.array(window.spec.shape) - 1)
        current = [self._matching_cluster(self._tasks[i]) for i in active]
        allocation = self._allocator.allocate(robot_cells[active], self._clusters, costmap, current)
        for k, i in enumerate(active):
            task = self._tasks[i]
            choice = allocation.cluster_of_robot[k]
            target = None if choice is None else self._clusters[choice]
            assigned = self._assign(i, target, poses[i, :2], now_s, choice != current[k])
            if not assigned and task.idle_since_s is None:
                task.idle_since_s = now_s
        # Done once every robot has had nothing to do for a while after the map has begun:
        # frontiers briefly vanish while a robot stands on the last one it was sent to.
        idle_since = [self._tasks[i].idle_since_s for i in active]
        explored = (
            len(self._mapper) > 0
            and all(s is not None for s in idle_since)
            and now_s - max(idle_since) >= self._config.algorithms.server.finish_after_idle_s
        )
        if explored:
            self._explored_s = now_s
            server = self._config.algorithms.server
            if server.patrol_s > 0 and self._values is not None:
                # Waypoints in the open, a robot radius clear of the lethal band.
                clear_m = 2 * self._config.robots.radius_m
                free = (window.crop(self._values) == FREE) & (costmap.distance_m >= clear_m)
                self._patrol = Patrol.over(
                    free, window.spec, server.patrol_spacing_m, poses[active[0]], now_s,
                    self._robot_count,
                )  # fmt: skip
            self._finished = self._patrol is None

    def _assign(
        self, robot: int, target: FrontierCluster | None, xy_m: np.ndarray, now_s: float,
        changed: bool,
    ) -> bool:  # fmt: skip
        """Plan the robot's global path to ``target``; without a target or a path to it
        the robot has neither. Returns whether it has one."""
        costmap, window, task = self._costmap, self._window, self._tasks[robot]
        assert costmap is not None and window is not None
        path = None
        if target is not None:
            try:
                path = self._global_planner.plan(
                    task.recovery.penalize(costmap.cost, window.spec), costmap.lethal,
                    window.spec, xy_m, target.target_m,
                )  # fmt: skip
            except NoPathError:
                path = None
        if path is None:
            task.cluster, task.path_m = None, None
            return False
        task.cluster = target
        task.path_m = np.vstack([xy_m, path])
        task.recovery.replanned(now_s, changed, remaining_length_m(task.path_m, xy_m))
        task.idle_since_s = None
        return True

    def _drive_patrol(self, active: list[int], poses: np.ndarray, now_s: float) -> None:
        """Each robot on along the tour; finished when the patrol has lasted its time."""
        assert self._patrol is not None
        for i in active:
            old = self._tasks[i].cluster
            reached = old is not None and self._tasks[i].path_m is None
            for waypoint in self._patrol.goals(i, reached):
                changed = old is None or not np.array_equal(old.target_m, waypoint.target_m)
                if self._assign(i, waypoint, poses[i, :2], now_s, changed):
                    break
        self._finished = now_s - self._patrol.started_s >= self._config.algorithms.server.patrol_s

    def _matching_cluster(self, task: RobotTask) -> int | None:
        """The current cluster that continues the robot's goal: its target is nearest the
        old target, within the goal tolerance plus the clusterer's linkage."""
        if task.cluster is None or not self._clusters:
            return None
        targets = np.array([c.target_m for c in self._clusters])
        gaps = np.linalg.norm(targets - task.cluster.target_m, axis=1)
        best = int(np.argmin(gaps))
        tolerance_m = self._config.algorithms.server.goal_tolerance_m + self._clusterer.linkage_m
        return best if gaps[best] <= tolerance_m else None

    def _local_plan(self, poses: np.ndarray, now_s: float) -> list[tuple[float, float]]:
        """(v, omega) for every robot: recovery overrides, else the local planner."""
        costmap, window = self._costmap, self._window
        if costmap is None or window is None:
            return [(0.0, 0.0)] * self._robot_count
        planning = self._config.algorithms.planning
        tolerance = self._config.algorithms.server.goal_tolerance_m
        # The distance field is to cell centres, walls are cell squares: half a cell
        # diagonal less makes the planners' clearance a lower bound of the truth.
        res = window.spec.resolution_m
        field = DistanceField(
            np.maximum(costmap.distance_m - res / math.sqrt(2.0), 0.0), window.spec
        )
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
        planned = self._local_planner.plan(states, goals, field)
        commands = [overrides.get(i, (float(v), float(w))) for i, (v, w) in enumerate(planned)]
        for i in self._lost:
            commands[i] = (0.0, 0.0)
        for i, task in enumerate(self._tasks):
            task.velocity = commands[i]
        return commands
