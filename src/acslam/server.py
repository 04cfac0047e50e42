"""The centralized server: one step of the thesis's pipeline (Fig. 4.2), wiring only.

ingest robot messages -> SLAM update -> map update (following pose corrections) ->
costmap -> frontiers and clusters -> (at the replanning rate, or when a robot reached or
lost its goal) allocation and A* -> local planning for all robots -> velocity commands.

The server sees only :mod:`acslam.messages` and the map's extent (a deployment parameter,
like the thesis's fixed 40 m x 40 m grid); it never touches simulator ground truth.

The costmap, Dijkstra and A* run on a window of the grid around the known cells plus a
margin, not on the whole grid: early in a run the known area is a small part of it, and
planning time grows with the cells searched.
"""

from __future__ import annotations

import math
import time
from collections import defaultdict
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from acslam.config import ScenarioConfig
from acslam.exploration.allocation import allocate
from acslam.exploration.clustering import FrontierCluster, cluster_frontiers
from acslam.exploration.frontiers import EwfdFrontierDetector, active_radius_m
from acslam.grid import GridSpec
from acslam.mapping.costmap import Costmap, compute_costmap
from acslam.mapping.occupancy import UNKNOWN, TeamMap
from acslam.messages import (
    LandmarkObservations,
    LidarScan,
    OdometryIncrement,
    RobotMessage,
    VelocityCommand,
)
from acslam.planning.astar import NoPathError, lookahead_point, plan_path, remaining_length_m
from acslam.planning.dwa import DynamicWindowPlanner
from acslam.planning.fgp import FactorGraphPlanner
from acslam.planning.field import DistanceField, RobotState
from acslam.planning.recovery import Recovery
from acslam.slam.backend import SlamBackend
from acslam.slam.lidar_constraints import LidarConstraints


@dataclass(frozen=True)
class Window:
    """A rectangle of the full grid: rows/cols ``[row0, row0 + spec.rows)`` etc."""

    row0: int
    col0: int
    spec: GridSpec

    def crop(self, array: np.ndarray) -> np.ndarray:
        return array[self.row0 : self.row0 + self.spec.rows, self.col0 : self.col0 + self.spec.cols]

    def to_local(self, cells: np.ndarray) -> np.ndarray:
        return np.asarray(cells) - np.array([self.row0, self.col0])


def known_window(values: np.ndarray, spec: GridSpec, margin_m: float) -> Window:
    """The bounding box of the known cells, grown by ``margin_m`` and clipped to the grid."""
    rows = np.flatnonzero((values != UNKNOWN).any(axis=1))
    cols = np.flatnonzero((values != UNKNOWN).any(axis=0))
    if len(rows) == 0:
        return Window(0, 0, spec)
    margin = math.ceil(margin_m / spec.resolution_m)
    r0, r1 = max(rows[0] - margin, 0), min(rows[-1] + margin + 1, spec.rows)
    c0, c1 = max(cols[0] - margin, 0), min(cols[-1] + margin + 1, spec.cols)
    local = GridSpec(
        spec.origin_x_m + c0 * spec.resolution_m,
        spec.origin_y_m + r0 * spec.resolution_m,
        spec.resolution_m,
        int(r1 - r0),
        int(c1 - c0),
    )
    return Window(int(r0), int(c0), local)


@dataclass
class RobotTask:
    """What the server has decided for one robot."""

    recovery: Recovery
    cluster: FrontierCluster | None = None
    path_m: np.ndarray | None = None
    velocity: tuple[float, float] = (0.0, 0.0)
    idle_since_s: float | None = None


@dataclass
class ServerStatus:
    """What the server reports after a step (for progress bars and the run record)."""

    time_s: float
    frontier_cells: int
    clusters: int
    idle: tuple[bool, ...]
    finished: bool


@dataclass
class CycleTimer:
    """Wall time per module per server step, in seconds."""

    samples: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))

    @contextmanager
    def measure(self, module: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.samples[module].append(time.perf_counter() - start)


class Server:
    """Localizes, maps, explores and plans for the whole team from robot messages."""

    def __init__(self, config: ScenarioConfig, starts: np.ndarray, map_spec: GridSpec) -> None:
        self.config = config
        algorithms = config.algorithms
        self.robot_count = len(starts)
        self.map_spec = map_spec
        self.slam = SlamBackend(algorithms.slam, {i: np.asarray(s) for i, s in enumerate(starts)})
        self.team_map = TeamMap(map_spec, algorithms.mapping)
        self.lidar = LidarConstraints(algorithms.scan_matching)
        self.frontiers = EwfdFrontierDetector(map_spec, active_radius_m(algorithms.mapping))
        self.tasks = [RobotTask(Recovery(algorithms.planning)) for _ in range(self.robot_count)]
        self.timer = CycleTimer()
        if algorithms.planning.local_planner == "fgp":
            self._fgp: FactorGraphPlanner | None = FactorGraphPlanner(
                algorithms.planning, config.robots
            )
        else:
            self._fgp = None
        self._dwa = DynamicWindowPlanner(algorithms.planning, config.robots)
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
        self.finished = False
        self.lost: dict[int, float] = {}

    def mark_lost(self, robot_id: int, now_s: float) -> None:
        """Give up on a robot that stopped answering (e.g. heartbeat timeout).

        Its frontier goes back to the pool at once, its planner state is dropped and it
        gets no more goals; the others plan around its last estimated pose, where it
        stands. Its map and trajectory so far stay.
        """
        if robot_id in self.lost:
            return
        self.lost[robot_id] = now_s
        task = self.tasks[robot_id]
        task.cluster, task.path_m, task.velocity = None, None, (0.0, 0.0)
        if self._fgp is not None:
            self._fgp.reset(robot_id)
        self._replan_now = True

    # ------------------------------------------------------------------ pipeline

    def step(self, messages: Iterable[RobotMessage], now_s: float) -> list[VelocityCommand]:
        """Run one server cycle on the messages received since the last one."""
        with self.timer.measure("cycle"):
            return self._step(messages, now_s)

    def _step(self, messages: Iterable[RobotMessage], now_s: float) -> list[VelocityCommand]:
        with self.timer.measure("slam"):
            scans = [
                (index, self._mappable(scan, self.slam.scan_pose(index)))
                for index, scan in self._ingest(messages)
            ]
            for index, scan in scans:
                self.lidar.add_scan(self.slam, index, scan)
            closures = 0
            if now_s >= self._next_map_update_s:
                closures = self.lidar.close_loops(self.slam)
            self.slam.update(extra_iterations=2 if closures else 0)
        with self.timer.measure("mapping"):
            self._integrate(scans)
        server = self.config.algorithms.server
        if now_s >= self._next_map_update_s:
            self._next_map_update_s = now_s + server.map_update_period_s
            with self.timer.measure("costmap"):
                self._update_costmap()
            with self.timer.measure("frontiers"):
                self._update_frontiers()
        poses = np.array([self.slam.latest_pose(i) for i in range(self.robot_count)])
        if self._replan_now or now_s >= self._next_replan_s:
            with self.timer.measure("allocation"):
                self._allocate(poses, now_s)
            self._next_replan_s = now_s + self.config.algorithms.planning.replan_period_s
            self._replan_now = False
        with self.timer.measure("local_planning"):
            commands = self._local_plan(poses, now_s)
        return [VelocityCommand(i, now_s, v, w) for i, (v, w) in enumerate(commands)]

    @property
    def costmap(self) -> tuple[Costmap, Window] | None:
        """The latest costmap and the grid window it covers (read-only, for live views)."""
        if self._costmap is None or self._window is None:
            return None
        return self._costmap, self._window

    @property
    def frontier_cells(self) -> np.ndarray:
        """(n, 2) ``[row, col]`` frontier cells of the full grid (read-only)."""
        return self._frontier_cells

    def status(self, now_s: float) -> ServerStatus:
        return ServerStatus(
            now_s,
            len(self._frontier_cells),
            len(self._clusters),
            tuple(t.idle_since_s is not None for t in self.tasks),
            self.finished,
        )

    # ------------------------------------------------------------------ SLAM and map

    def _ingest(self, messages: Iterable[RobotMessage]) -> list[tuple[int, LidarScan]]:
        scans = []
        for message in messages:
            if isinstance(message, OdometryIncrement):
                self.slam.add_odometry(message)
            elif isinstance(message, LandmarkObservations):
                self.slam.add_landmarks(message)
            elif isinstance(message, LidarScan):
                index = self.slam.add_scan(message)
                if index is not None:
                    scans.append((index, message))
        return scans

    def _mappable(self, scan: LidarScan, pose: np.ndarray) -> LidarScan:
        """The scan minus invalid (0) readings and beams that end on another robot.

        Robots are not walls: their returns would stay in the map after they moved on.
        """
        keep = scan.ranges > 0
        angles = scan.angles + pose[2]
        ends = pose[:2] + scan.ranges[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        reach = self.config.robots.radius_m + self.config.algorithms.server.robot_filter_margin_m
        for j in range(self.robot_count):
            if j != scan.robot_id:
                with np.errstate(invalid="ignore"):
                    keep &= ~(np.linalg.norm(ends - self.slam.latest_pose(j)[:2], axis=1) < reach)
        if keep.all():
            return scan
        return LidarScan(
            scan.robot_id, scan.stamp, scan.angles[keep], scan.ranges[keep], scan.range_max_m
        )

    def _integrate(self, scans: list[tuple[int, LidarScan]]) -> None:
        """Add new (mappable) scans at their keyframe-relative pose; move scans SLAM
        corrected."""
        for index, scan in scans:
            pose = self.slam.scan_pose(index)
            self.team_map.add_scan(scan.robot_id, index, scan.ranges, scan.angles, pose)
            self._new_scan_cells.append(self.map_spec.world_to_cell(pose[:2])[0])
        moved = self.slam.moved_keyframes()
        if moved:
            for index in self.slam.scans_of_keyframes(moved):
                self.team_map.move_scan(index, self.slam.scan_pose(index))
            self._corrected = True

    def _update_costmap(self) -> None:
        values = self.team_map.global_grid.to_occupancy_values()
        server = self.config.algorithms.server
        window = known_window(values, self.map_spec, server.window_margin_m)
        self._values = values
        self._window = window
        self._costmap = compute_costmap(
            window.crop(values),
            window.spec,
            self.config.algorithms.costmap,
            self.config.robots.radius_m,
        )

    def _update_frontiers(self) -> None:
        assert self._values is not None and self._window is not None and self._costmap is not None
        robot_cells = self.map_spec.world_to_cell(
            np.array([self.slam.latest_pose(i)[:2] for i in range(self.robot_count)])
        )
        scan_cells = None if self._corrected else np.array(self._new_scan_cells).reshape(-1, 2)
        self._frontier_cells = self.frontiers.update(self._values, robot_cells, scan_cells)
        self._new_scan_cells.clear()
        self._corrected = False
        window = self._window
        self._clusters = cluster_frontiers(
            window.to_local(self._frontier_cells),
            window.crop(self._values),
            window.spec,
            self._costmap,
            self.config.algorithms.exploration,
        )

    # ------------------------------------------------------------------ decisions

    def _allocate(self, poses: np.ndarray, now_s: float) -> None:
        """Assign clusters and plan a global path to each; a robot with none goes idle."""
        costmap, window = self._costmap, self._window
        if costmap is None or window is None:
            return
        robot_cells = window.spec.world_to_cell(poses[:, :2])
        robot_cells = np.clip(robot_cells, 0, np.array(window.spec.shape) - 1)
        active = [i for i in range(self.robot_count) if i not in self.lost]
        current = [self._matching_cluster(self.tasks[i]) for i in active]
        allocation = allocate(
            robot_cells[active],
            self._clusters,
            costmap,
            self.config.algorithms.allocation,
            current,
        )
        planning = self.config.algorithms.planning
        for k, i in enumerate(active):
            task = self.tasks[i]
            choice = allocation.cluster_of_robot[k]
            path = None
            if choice is not None:
                cluster = self._clusters[choice]
                try:
                    path = plan_path(
                        task.recovery.penalize(costmap.cost, window.spec),
                        costmap.lethal,
                        window.spec,
                        poses[i, :2],
                        cluster.target_m,
                        planning.astar_cost_weight,
                        planning.astar_max_snap_m,
                        planning.astar_shortcut,
                    )
                except NoPathError:
                    path = None
            if path is None:
                task.cluster, task.path_m = None, None
                if task.idle_since_s is None:
                    task.idle_since_s = now_s
                continue
            task.cluster = self._clusters[choice]
            task.path_m = np.vstack([poses[i, :2], path.points_m])
            task.recovery.replanned(
                now_s, choice != current[k], remaining_length_m(task.path_m, poses[i, :2])
            )
            task.idle_since_s = None
        # Done once every robot has had nothing to do for a while after the map has begun:
        # frontiers briefly vanish while a robot stands on the last one it was sent to.
        idle_since = [self.tasks[i].idle_since_s for i in active]
        self.finished = (
            len(self.team_map) > 0
            and all(s is not None for s in idle_since)
            and now_s - max(idle_since) >= self.config.algorithms.server.finish_after_idle_s
        )

    def _matching_cluster(self, task: RobotTask) -> int | None:
        """The current cluster that continues the robot's goal: its target is nearest the
        old target, within the goal tolerance plus the clustering radius."""
        if task.cluster is None or not self._clusters:
            return None
        targets = np.array([c.target_m for c in self._clusters])
        gaps = np.linalg.norm(targets - task.cluster.target_m, axis=1)
        best = int(np.argmin(gaps))
        server, exploration = self.config.algorithms.server, self.config.algorithms.exploration
        return best if gaps[best] <= server.goal_tolerance_m + exploration.dbscan_eps_m else None

    def _local_plan(self, poses: np.ndarray, now_s: float) -> list[tuple[float, float]]:
        """(v, omega) for every robot: recovery overrides, FGP jointly, or DWA each."""
        costmap, window = self._costmap, self._window
        if costmap is None or window is None:
            return [(0.0, 0.0)] * self.robot_count
        planning = self.config.algorithms.planning
        tolerance = self.config.algorithms.server.goal_tolerance_m
        # The distance field is to cell centres, walls are cell squares: half a cell
        # diagonal less makes the planners' clearance a lower bound of the truth.
        res = window.spec.resolution_m
        field = DistanceField(
            np.maximum(costmap.distance_m - res / math.sqrt(2.0), 0.0), window.spec
        )
        reach_m = planning.horizon_s * self.config.robots.max_v_mps
        # Every robot takes part, so the others plan around it: a robot without a path
        # holds its position as its goal (and yields if another one comes close).
        states, goals, overrides = [], [], {}
        for i, task in enumerate(self.tasks):
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
                if self._fgp is not None:
                    self._fgp.reset(i)
            if step.command is not None:
                overrides[i] = step.command
            goals[i] = lookahead_point(task.path_m, state.xy_m, reach_m)
        if self._fgp is not None:
            planned = self._fgp.plan(states, goals, field).commands
        else:
            planned = [self._dwa_command(i, states, goals, field) for i in range(len(states))]
        commands = [overrides.get(i, (float(v), float(w))) for i, (v, w) in enumerate(planned)]
        for i in self.lost:
            commands[i] = (0.0, 0.0)
        for i, task in enumerate(self.tasks):
            task.velocity = commands[i]
        return commands

    def _dwa_command(
        self,
        k: int,
        states: list[RobotState],
        goals: list[np.ndarray],
        field: DistanceField,
    ) -> tuple[float, float]:
        others = [s for j, s in enumerate(states) if j != k]
        xy = np.array([s.xy_m for s in others]).reshape(-1, 2)
        velocity = np.array(
            [[s.v_mps * math.cos(s.theta_rad), s.v_mps * math.sin(s.theta_rad)] for s in others]
        ).reshape(-1, 2)
        return self._dwa.command(states[k], goals[k], field, xy, velocity)
