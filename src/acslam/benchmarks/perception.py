"""Map-side benchmarks: scan integration, costmap, scan matching, frontiers, allocation."""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

import numba
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from acslam.benchmarks.core import Figure, median_ms
from acslam.config import (
    CostmapConfig,
    DungeonWorld,
    LidarConfig,
    MappingConfig,
    RobotsConfig,
    ScanMatchingConfig,
    ThesisWorld,
    parse_scenario,
)
from acslam.exploration.allocation import cluster_distances_m
from acslam.exploration.clustering import FrontierCluster, cluster_frontiers
from acslam.exploration.frontiers import (
    EwfdFrontierDetector,
    active_radius_m,
    reachable_frontier_cells,
)
from acslam.exploration.params import DbscanParams, FactorGraphParams
from acslam.geometry import compose, transform_points
from acslam.grid import OCCUPIED, UNKNOWN, GridSpec, Window, bresenham
from acslam.mapping.correlative import (
    HeadingTable,
    LikelihoodPyramid,
    Match,
    SearchWindow,
    best_match,
    exhaustive_match,
)
from acslam.mapping.costmap import CostmapUpdater, compute_costmap
from acslam.mapping.occupancy import LogOddsGrid, TeamMap, grid_spec_for_bounds
from acslam.mapping.params import SubmapMappingConfig
from acslam.mapping.scan_matching import match_scans, prepare_scan
from acslam.mapping.submaps import SubmapTeamMap
from acslam.messages import LidarScan
from acslam.pipeline.registry import ALLOCATORS
from acslam.pipeline.server import costmap_reach_m
from acslam.planning.astar import astar_cells, snap_to_free
from acslam.planning.travel_graph import TravelGraphBuilder
from acslam.sim.lidar import LidarSensor
from acslam.worlds.generators import build_world
from acslam.worlds.mapio import world_cells
from acslam.worlds.world import World


def _room_ranges(pose: np.ndarray, angles: np.ndarray, half_size_m: float) -> np.ndarray:
    """Ranges to the walls of a square room centred at the origin, inf beyond 8 m."""
    dx, dy = np.cos(pose[2] + angles), np.sin(pose[2] + angles)
    with np.errstate(divide="ignore"):
        tx = (np.sign(dx) * half_size_m - pose[0]) / dx
        ty = (np.sign(dy) * half_size_m - pose[1]) / dy
    ranges = np.minimum(np.abs(tx), np.abs(ty))
    ranges[ranges > 8.0] = np.inf
    return ranges


def _correction_figures(
    scans: list[tuple[np.ndarray, np.ndarray]], angles: np.ndarray, spec: GridSpec, quick: bool
) -> Figure:
    """One correction of 50 scans: a submap re-placed whole against each scan re-cast."""
    config = SubmapMappingConfig(max_range_m=8.0, submap_travel_m=10.0, submap_max_scans=50)
    exact, submaps = TeamMap(config, spec=spec), SubmapTeamMap(config, spec=spec)
    for index, (ranges, pose) in enumerate(scans):
        exact.add_scan(0, index, ranges, angles, pose)
        submaps.add_scan(0, index, ranges, angles, pose)
    shifts = iter(range(10**9))

    def shifted(pose: np.ndarray, k: int) -> np.ndarray:
        return pose + np.array([0.02, 0.01, 0.002]) * (k % 2)

    def move_exact() -> None:
        k = next(shifts)
        for index, (_, pose) in enumerate(scans):
            exact.move_scan(index, shifted(pose, k))

    def move_submap() -> None:
        submaps.move_scan(0, shifted(scans[0][1], next(shifts)))

    exact_ms = median_ms(move_exact, 3 if quick else 10)
    submap_ms = median_ms(move_submap, 10 if quick else 50)
    return Figure(
        "mapping",
        f"correction of {len(scans)} scans: one submap re-placed",
        submap_ms,
        "ms",
        "TeamMap.move_scan of each scan",
        exact_ms,
    )


def bench_mapping(quick: bool) -> list[Figure]:
    """Scan integration and costmap on the thesis's 800 x 800 grid, against ``np.copy`` of it.

    Goals (10 Hz LiDAR, thesis-scale maps): <= 2 ms per 360-beam scan, <= 20 ms per costmap.
    """
    spec = grid_spec_for_bounds(-20.0, -20.0, 20.0, 20.0, 0.05)
    grid = LogOddsGrid(spec, MappingConfig(max_range_m=8.0))
    reference = np.zeros(spec.shape)
    copy_ms = median_ms(lambda: np.copy(reference), 50 if quick else 200)
    rng = np.random.default_rng(0)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    poses = [np.array([*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi)]) for _ in range(50)]
    scans = [(_room_ranges(pose, angles, 7.0), pose) for pose in poses]
    for ranges, pose in scans:
        grid.integrate(ranges, angles, pose)
    index = iter(range(10**9))

    def integrate_one() -> None:
        ranges, pose = scans[next(index) % len(scans)]
        grid.integrate(ranges, angles, pose)

    scan_ms = median_ms(integrate_one, 60 if quick else 300)
    submap_ms = _submap_scan_ms(spec, angles, quick)
    team = TeamMap(grid.config, spec=spec)
    team.add_scan(0, "moved", scans[0][0], angles, scans[0][1])
    shifts = iter(range(10**9))

    def move_one() -> None:
        team.move_scan("moved", scans[0][1] + (0.02 if next(shifts) % 2 else 0.0))

    move_ms = median_ms(move_one, 20 if quick else 100)
    correction = _correction_figures(scans, angles, spec, quick)
    values = grid.to_occupancy_values()
    costmap_ms = median_ms(
        lambda: compute_costmap(values, spec, CostmapConfig(), RobotsConfig().radius_m),
        5 if quick else 30,
    )
    edt_ms = median_ms(lambda: ndimage.distance_transform_edt(values != 100), 5 if quick else 30)
    update_ms, fresh_ms = _costmap_update_figures(values, spec, quick)
    reference_name = f"np.copy of the {spec.rows}x{spec.cols} float64 grid"
    return [
        Figure(
            "mapping",
            "scan integration (360 beams, 8 m)",
            scan_ms,
            "ms",
            reference_name,
            copy_ms,
            "goal <= 2 ms",
        ),
        Figure(
            "mapping",
            "SubmapTeamMap.add_scan (global + robot + submap), driving 3 cm per scan",
            submap_ms,
            "ms",
            "scan integration into one grid",
            scan_ms,
        ),
        Figure(
            "mapping", "TeamMap.move_scan (global + robot)", move_ms, "ms", reference_name, copy_ms
        ),
        correction,
        Figure(
            "mapping",
            "costmap (EDT + decay + lethal)",
            costmap_ms,
            "ms",
            "scipy EDT of the same grid",
            edt_ms,
            "goal <= 20 ms",
        ),
        Figure(
            "mapping",
            "costmap update after a 0.5 m obstacle appeared or went (CostmapUpdater)",
            update_ms,
            "ms",
            "the whole costmap afresh, same reach",
            fresh_ms,
        ),
    ]


def _submap_scan_ms(spec: GridSpec, angles: np.ndarray, quick: bool) -> float:
    """A scan into the submaps mapper, the robot driving 3 cm and turning 0.02 rad per
    scan (so submaps open and close as in a run)."""
    poses = [np.array([-3.0 + 0.03 * k, -1.0 + 0.01 * k, 0.02 * k]) for k in range(200)]
    scans = [(_room_ranges(pose, angles, 7.0), pose) for pose in poses]
    submaps = SubmapTeamMap(SubmapMappingConfig(max_range_m=8.0), spec=spec)
    index = iter(range(10**9))

    def add_one() -> None:
        k = next(index)
        ranges, pose = scans[k % len(scans)]
        submaps.add_scan(0, k, ranges, angles, pose)

    return median_ms(add_one, 60 if quick else 300)


def _costmap_update_figures(values: np.ndarray, spec: GridSpec, quick: bool) -> tuple[float, float]:
    """The server's costmap update where a box appears and vanishes in turn, and the same
    costmap computed afresh (both with the server's default reach)."""
    config = parse_scenario({"world": {"generator": "dungeon"}}, "defaults")
    reach_m = costmap_reach_m(config, spec)
    radius_m = config.robots.radius_m
    boxed = values.copy()
    boxed[395:405, 395:405] = OCCUPIED
    updater = CostmapUpdater(config.algorithms.costmap, radius_m, reach_m)
    whole = Window(0, 0, spec)
    updater.update(values, whole)
    turns = iter([boxed, values] * 10**6)
    update_ms = median_ms(lambda: updater.update(next(turns), whole), 10 if quick else 50)
    fresh_ms = median_ms(
        lambda: compute_costmap(values, spec, config.algorithms.costmap, radius_m, reach_m),
        5 if quick else 30,
    )
    return update_ms, fresh_ms


def _room_world() -> World:
    """An 8 m x 6 m room with four boxes, 0.05 m cells."""
    occupied = np.zeros((122, 162), dtype=bool)
    occupied[0, :] = occupied[-1, :] = occupied[:, 0] = occupied[:, -1] = True
    for row, col, height, width in (
        (20, 30, 10, 14),
        (80, 40, 8, 8),
        (50, 110, 15, 6),
        (95, 120, 6, 20),
    ):
        occupied[row : row + height, col : col + width] = True
    return World("room", GridSpec(0.0, 0.0, 0.05, 122, 162), occupied)


def bench_scan_matching(quick: bool) -> list[Figure]:
    """Point-to-line ICP of two simulated scans against building a cKDTree of one (goal 5 ms)."""
    config = ScanMatchingConfig()
    sensor = LidarSensor(LidarConfig(), _room_world(), np.random.default_rng(0))
    pose_a = np.array([4.0, 3.5, 0.3])
    pose_b = compose(pose_a, np.array([0.3, -0.2, 0.15]))
    no_discs = np.zeros((0, 3))
    scan_a, scan_b = (sensor.scan(0, 0.0, tuple(pose), no_discs, -1) for pose in (pose_a, pose_b))
    reference = prepare_scan(scan_a.angles, scan_a.ranges, config)
    query = prepare_scan(scan_b.angles, scan_b.ranges, config)
    guess = np.array([0.3, -0.2, 0.15]) + np.array([0.05, -0.05, 0.03])
    repeats = 50 if quick else 300
    tree = cKDTree(reference.points_m)
    tree_ms = median_ms(lambda: cKDTree(reference.points_m), repeats)
    match_ms = median_ms(lambda: match_scans(reference, query, guess, config), repeats)
    moved = transform_points(guess, query.points_m)
    gate_m = config.gate_min_m
    grid_ms = median_ms(lambda: reference.grid.nearest_within(moved, gate_m), repeats)
    tree_query_ms = median_ms(lambda: tree.query(moved, distance_upper_bound=gate_m), repeats)
    return [
        Figure(
            "scan matching",
            "match_scans (prepared 360-beam scans)",
            match_ms,
            "ms",
            "cKDTree build of one scan",
            tree_ms,
            "goal <= 5 ms",
        ),
        Figure(
            "scan matching",
            "nearest reference points within the gate, grid (one ICP iteration)",
            grid_ms,
            "ms",
            "cKDTree query of the same points",
            tree_query_ms,
            f"{len(moved)} points against {len(reference.points_m)}, {gate_m} m gate",
        ),
        *_global_matching_figures(quick, tree_ms),
    ]


def _global_matching_figures(quick: bool, tree_ms: float) -> list[Figure]:
    """Branch and bound against the exhaustive search of the same poses (a window 1 m and
    0.5 rad around the truth), over the whole thesis labyrinth at every heading, and a
    merge's questions in a pinned window: by a heading table against branch and bound."""
    world = build_world(ThesisWorld(generator="thesis", experiment=4), 0)
    pyramid = LikelihoodPyramid.from_occupancy(world_cells(world), world.spec, 0.1, 7)
    sensor = LidarSensor(LidarConfig(), world, np.random.default_rng(0))
    pose = np.array([14.6, 22.0, 2.0])
    scan = sensor.scan(0, 0.0, tuple(pose), np.zeros((0, 3)), -1)
    seen = np.isfinite(scan.ranges) & (scan.ranges > 0)
    points = np.column_stack(
        [
            scan.ranges[seen] * np.cos(scan.angles[seen]),
            scan.ranges[seen] * np.sin(scan.angles[seen]),
        ]
    )
    window = SearchWindow.around(pose, points, 1.0, 0.5)
    repeats = 3 if quick else 10
    bnb_ms = median_ms(lambda: best_match(points, pyramid, window), repeats)
    exhaustive_ms = median_ms(lambda: exhaustive_match(points, pyramid, window), 1 if quick else 3)
    fast, slow = best_match(points, pyramid, window), exhaustive_match(points, pyramid, window)
    same = fast is not None and slow is not None and np.array_equal(fast.pose, slow.pose)
    everywhere = SearchWindow.covering(world.spec, points)
    global_ms = median_ms(lambda: best_match(points, pyramid, everywhere), repeats)
    # A merge's questions in a pinned window (the seen robot within 0.5 m, every heading):
    # the best pose, then five times the best 1 m or 0.35 rad away from those found.
    pinned = SearchWindow.pinned(np.zeros(2), pose[:2], 0.5)

    def questions(best: Callable[..., Match | None]) -> list[Match | None]:
        found: list[Match | None] = []
        for _ in range(6):
            found.append(best(0.0, tuple(m for m in found if m is not None), 1.0, 0.35))
        return found

    def by_table() -> list[Match | None]:
        return questions(HeadingTable(points, pyramid, pinned).best)

    def by_branch_and_bound() -> list[Match | None]:
        return questions(partial(best_match, points, pyramid, pinned))

    table_ms = median_ms(by_table, repeats)
    bnb_questions_ms = median_ms(by_branch_and_bound, repeats)
    same_answers = all(
        a is not None and b is not None and np.array_equal(a.pose, b.pose)
        for a, b in zip(by_table(), by_branch_and_bound(), strict=True)
    )
    return [
        Figure(
            "scan matching",
            "global match, branch and bound (1 m, 0.5 rad window)",
            bnb_ms,
            "ms",
            "exhaustive search of the same poses",
            exhaustive_ms,
            f"{len(points)} points; " + ("the same pose found" if same else "POSES DIFFER"),
        ),
        Figure(
            "scan matching",
            "global match, whole 40 m x 40 m labyrinth, every heading",
            global_ms,
            "ms",
            "cKDTree build of one scan",
            tree_ms,
            "no pose guess",
        ),
        Figure(
            "scan matching",
            "a merge's six questions in a pinned window, heading table",
            table_ms,
            "ms",
            "branch and bound per question",
            bnb_questions_ms,
            f"{len(points)} points, 1 m window, every heading; "
            + ("the same poses" if same_answers else "POSES DIFFER"),
        ),
    ]


def _scripted_paths(world: World, rng: np.random.Generator, rounds: int) -> list[np.ndarray]:
    """Per start pose, (rounds, 2) positions every 0.25 m along A* legs to random goals."""
    lethal = world.clearance_m < 0.25
    cost = np.zeros(world.spec.shape)
    free_cells = np.argwhere(~lethal & world.reachable_free(*world.default_starts[0, :2]))
    stride = max(1, round(0.25 / world.spec.resolution_m))
    paths = []
    for start in world.default_starts:
        cell = tuple(int(v) for v in world.spec.world_to_cell(start[:2])[0])
        current = tuple(free_cells[np.argmin(((free_cells - cell) ** 2).sum(axis=1))])
        points: list[np.ndarray] = []
        while len(points) < rounds:
            goal = tuple(int(v) for v in free_cells[rng.integers(len(free_cells))])
            cells, _ = astar_cells(cost, lethal, current, goal, world.spec.resolution_m, 0.0)
            points.extend(world.spec.cell_to_world(cells[::stride]))
            current = goal
        paths.append(np.array(points[:rounds]))
    return paths


def _both_detectors(
    detector: EwfdFrontierDetector, values: np.ndarray, robot_cells: np.ndarray, step: int
) -> tuple[np.ndarray, tuple[float, float]]:
    """EWFD's update and the naive scan on the same map, which must give the same cells;
    returns EWFD's cells and the seconds each took."""
    t0 = time.perf_counter()
    got = detector.update(values, robot_cells, robot_cells)
    t1 = time.perf_counter()
    expected = reachable_frontier_cells(values, robot_cells)
    t2 = time.perf_counter()
    if not np.array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], expected):
        raise AssertionError(f"EWFD and the naive scan disagree at round {step}")
    return got, (t1 - t0, t2 - t1)


def bench_frontiers(quick: bool) -> tuple[list[Figure], dict]:
    """Incremental EWFD against the naive full-grid scan on the same map, thesis world 4.

    Three robots follow scripted A* paths, each scanning every 0.25 m; after every round
    both detectors run and must return the same cells. Also returns the final map for
    the clustering and allocation benchmark.
    """
    rounds = 40 if quick else 240
    world = build_world(ThesisWorld(generator="thesis", experiment=4), 0)
    rng = np.random.default_rng(0)
    mapping = MappingConfig()
    team = TeamMap(mapping, spec=world.spec)
    sensors = [LidarSensor(LidarConfig(), world, np.random.default_rng(k)) for k in range(3)]
    paths = _scripted_paths(world, rng, rounds)
    detector = EwfdFrontierDetector(world.spec, active_radius_m(mapping))
    no_discs = np.zeros((0, 3))
    ewfd_s, naive_s = [], []
    for step in range(rounds):
        positions = np.array([path[step] for path in paths])
        for k, sensor in enumerate(sensors):
            pose = np.array([*positions[k], rng.uniform(-np.pi, np.pi)])
            scan = sensor.scan(k, float(step), tuple(pose), no_discs, -1)
            team.add_scan(k, (k, step), scan.ranges, scan.angles, pose, scan.range_max_m)
        values = team.occupancy_values()
        robot_cells = world.spec.world_to_cell(positions)
        got, seconds = _both_detectors(detector, values, robot_cells, step)
        if step > 0:  # the first update is the full initial search
            ewfd_s.append(seconds[0])
            naive_s.append(seconds[1])
    figures = [
        Figure(
            "exploration",
            f"EWFD frontier update ({rounds} rounds x 3 scans, 800x800)",
            1e3 * float(np.mean(ewfd_s)),
            "ms",
            "naive full-grid frontier scan",
            1e3 * float(np.mean(naive_s)),
            "same cells every round; goal ratio <= 0.1",
        ),
    ]
    return figures, {"world": world, "values": values, "frontier": got}


def _reveal(
    values: np.ndarray, truth: np.ndarray, spec: GridSpec, pose: np.ndarray, scan: LidarScan
) -> None:
    """Make the true cells along each beam of ``scan``, taken at ``pose``, known up to its
    return or the mapping range: what integrating the scan would make of them, without
    the noise."""
    max_range_m = MappingConfig().max_range_m
    ranges = np.minimum(np.nan_to_num(scan.ranges, posinf=max_range_m), max_range_m)
    x, y, theta = pose
    ends = np.column_stack(
        [x + ranges * np.cos(theta + scan.angles), y + ranges * np.sin(theta + scan.angles)]
    )
    r0, c0 = spec.world_to_cell(np.array([[x, y]]))[0]
    for r1, c1 in spec.world_to_cell(ends):
        cells = bresenham(int(r0), int(c0), int(r1), int(c1))
        cells = cells[spec.contains(cells)]
        values[cells[:, 0], cells[:, 1]] = truth[cells[:, 0], cells[:, 1]]


def bench_frontiers_large(quick: bool) -> list[Figure]:
    """EWFD against the naive scan mid-exploration of a large dungeon: 200 m x 200 m at
    0.05 m (4000 x 4000; 100 m, 2000 x 2000 with ``quick``), 280 rooms.

    The team has scanned from 600 (150) random poses within 50 m (25 m) of the first start
    pose, which leaves a frontier of thousands of cells, as in a real run. Three robots
    then drive from frontier cells towards random free goals beyond, scanning every
    0.25 m; a scan makes the true cells along its beams known, as integrating it would.
    Both detectors must return the same cells after every round.
    """
    size_m, explored_m, scans, rounds = (100.0, 25.0, 150, 10) if quick else (200.0, 50.0, 600, 30)
    no_discs = np.zeros((0, 3))
    world = build_world(
        DungeonWorld(generator="dungeon", width_m=size_m, height_m=size_m, room_count=280), 0
    )
    spec = world.spec
    truth = world_cells(world)
    start = world.default_starts[0, :2]
    reachable = world.reachable_free(*start)
    rows, cols = np.indices(spec.shape, sparse=True)
    centre = spec.world_to_cell(start)[0]
    radius_cells = explored_m / spec.resolution_m
    near = (rows - centre[0]) ** 2 + (cols - centre[1]) ** 2 <= radius_cells**2
    lethal = world.clearance_m < 0.25
    rng = np.random.default_rng(0)
    sensor = LidarSensor(LidarConfig(), world, np.random.default_rng(1))
    values = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    scanned_from = np.argwhere(reachable & near & ~lethal)
    for k, cell in enumerate(scanned_from[rng.choice(len(scanned_from), scans, replace=False)]):
        pose = np.array([*spec.cell_to_world(cell)[0], rng.uniform(-np.pi, np.pi)])
        _reveal(values, truth, spec, pose, sensor.scan(0, float(k), tuple(pose), no_discs, -1))
    detector = EwfdFrontierDetector(spec, active_radius_m(MappingConfig()))
    frontier = detector.update(values, centre[None, :])
    beyond = np.argwhere(reachable & ~near & ~lethal)
    starts = frontier[rng.choice(len(frontier), 3, replace=False)]
    stride = round(0.25 / spec.resolution_m)
    paths = []
    for cell in starts:
        start_cell = tuple(int(v) for v in snap_to_free(lethal | ~reachable, cell, 40))
        goal = tuple(int(v) for v in beyond[rng.integers(len(beyond))])
        cells, _ = astar_cells(
            np.zeros(spec.shape), lethal, start_cell, goal, spec.resolution_m, 0.0
        )
        paths.append(cells[::stride][:rounds])
    ewfd_s, naive_s = [], []
    for step in range(rounds):
        robot_cells = np.array([path[min(step, len(path) - 1)] for path in paths])
        for k, cell in enumerate(robot_cells):
            pose = np.array([*spec.cell_to_world(cell)[0], rng.uniform(-np.pi, np.pi)])
            _reveal(
                values, truth, spec, pose, sensor.scan(k, float(step), tuple(pose), no_discs, -1)
            )
        got, seconds = _both_detectors(detector, values, robot_cells, step)
        ewfd_s.append(seconds[0])
        naive_s.append(seconds[1])
    return [
        Figure(
            "exploration",
            f"EWFD frontier update mid-exploration ({rounds} rounds x 3 scans, "
            f"{spec.rows}x{spec.cols}, {len(frontier)} -> {len(got)} frontier cells)",
            1e3 * float(np.mean(ewfd_s)),
            "ms",
            "naive full-grid frontier scan",
            1e3 * float(np.mean(naive_s)),
            "same cells every round; goal ratio <= 0.01 at 4000x4000",
        )
    ]


def bench_allocation(
    quick: bool, world: World, values: np.ndarray, frontier: np.ndarray
) -> list[Figure]:
    """DBSCAN clustering and every registered allocator (20 clusters) against an 800x800
    ``np.sort``."""
    data = np.random.default_rng(0).random((800, 800))
    sort_ms = median_ms(lambda: np.sort(data, axis=1), 5)
    reference = "np.sort of 800x800 float64 rows"
    spec = world.spec
    costmap = compute_costmap(values, spec, CostmapConfig(), RobotsConfig().radius_m)
    exploration = DbscanParams()
    clusters = cluster_frontiers(frontier, values, spec, costmap, exploration)
    figures = [
        Figure(
            "exploration",
            f"DBSCAN clustering ({len(frontier)} frontier cells)",
            median_ms(lambda: cluster_frontiers(frontier, values, spec, costmap, exploration), 3),
            "ms",
            reference,
            sort_ms,
        ),
    ]
    rng = np.random.default_rng(1)
    reachable = np.argwhere((values == 0) & ~costmap.lethal)
    extra = reachable[rng.choice(len(reachable), 20, replace=False)]
    clusters = (
        clusters
        + [
            FrontierCluster(
                cell[None, :],
                spec.cell_to_world(cell)[0],
                cell,
                spec.cell_to_world(cell)[0],
                int(rng.integers(5, 60)),
                0,
            )
            for cell in extra
        ]
    )[:20]
    for robots in (3,) if quick else (3, 5, 8):
        cells = reachable[rng.choice(len(reachable), robots, replace=False)]
        for name in ALLOCATORS.names():
            params = ALLOCATORS.get(name).params()
            allocator = ALLOCATORS.create(params)
            run = partial(allocator.allocate, cells, clusters, costmap)
            figures.append(
                Figure(
                    "exploration",
                    f"allocation {name}, {robots} robots x 20 clusters",
                    median_ms(run, 2),
                    "ms",
                    reference,
                    sort_ms,
                    "straight-line distances, no Dijkstra"
                    if getattr(params, "distance_metric", None) == "euclidean-unchecked"
                    else "includes one Dijkstra per robot",
                )
            )
    return figures


def bench_travel_distances(quick: bool) -> list[Figure]:
    """Allocation's robot-to-cluster path lengths through the travel graph (the
    ``travel-graph`` distance metric) against one exact Dijkstra per robot, on a fully
    known dungeon: 100 m x 100 m at 0.05 m (2000 x 2000), 10 robots, 50 targets.

    Twice: with a fresh graph (the first replan, or a window that grew), and at a replan
    after a map update, where the allocator's builder relabels only the blocks that
    changed. The update: an obstacle 0.5 m across appears 1.25 m from each robot, and
    the next one clears them again. The replan once more on one thread: the robots'
    searches run on up to ``NUMBA_NUM_THREADS`` threads."""
    size_m, robots = (50.0, 3) if quick else (100.0, 10)
    world = build_world(
        DungeonWorld(generator="dungeon", width_m=size_m, height_m=size_m, room_count=int(size_m)),
        0,
    )
    spec = world.spec
    values = world_cells(world)
    costmap = compute_costmap(values, spec, CostmapConfig(), RobotsConfig().radius_m)
    rng = np.random.default_rng(0)
    free = np.argwhere(~costmap.lethal)
    cells = free[rng.choice(len(free), robots, replace=False)]
    targets = free[rng.choice(len(free), 50, replace=False)]
    clusters = [
        FrontierCluster(cell[None, :], centre_m, cell, centre_m, 1, 0)
        for cell, centre_m in zip(targets, spec.cell_to_world(targets), strict=True)
    ]
    obstacles = values.copy()
    rows, cols = np.ogrid[: spec.rows, : spec.cols]
    for r, c in cells:
        obstacles[(rows - r - 25) ** 2 + (cols - c) ** 2 <= 5**2] = OCCUPIED
    updated = compute_costmap(obstacles, spec, CostmapConfig(), RobotsConfig().radius_m)
    exact_params = FactorGraphParams()
    graph_params = FactorGraphParams(distance_metric="travel-graph")
    exact = cluster_distances_m(cells, clusters, costmap, exact_params)
    approx = cluster_distances_m(cells, clusters, costmap, graph_params)
    if not np.array_equal(np.isfinite(exact), np.isfinite(approx)):
        raise AssertionError("the travel graph and Dijkstra disagree on what is reachable")
    reachable = np.isfinite(exact)
    relative = np.abs(approx - exact)[reachable] / np.maximum(exact[reachable], 1e-9)
    builder = TravelGraphBuilder()
    costmaps = iter([updated, costmap] * 10**6)

    def replan() -> None:
        cluster_distances_m(cells, clusters, next(costmaps), graph_params, builder)

    threads = numba.config.NUMBA_NUM_THREADS
    replan_ms = median_ms(replan, 6)
    numba.config.NUMBA_NUM_THREADS = 1
    try:
        one_thread_ms = median_ms(replan, 6)
    finally:
        numba.config.NUMBA_NUM_THREADS = threads
    exact_ms = median_ms(partial(cluster_distances_m, cells, clusters, costmap, exact_params), 1)
    setup = f"{robots} robots x 50 clusters, {spec.rows}x{spec.cols}"
    goal = "goal <= 20 ms at 10 robots, 2000x2000"
    return [
        Figure(
            "exploration",
            f"allocation distances, travel graph, fresh graph, {setup}",
            median_ms(partial(cluster_distances_m, cells, clusters, costmap, graph_params), 3),
            "ms",
            "one exact Dijkstra per robot",
            exact_ms,
            f"same reachability; length error {100 * np.percentile(relative, 95):.1f} % p95, "
            f"{100 * relative.max():.1f} % max",
        ),
        Figure(
            "exploration",
            f"allocation distances, travel graph, replan after a map update, {setup}, "
            f"{threads} threads",
            replan_ms,
            "ms",
            "one exact Dijkstra per robot",
            exact_ms,
            goal,
        ),
        Figure(
            "exploration",
            f"allocation distances, travel graph, replan after a map update, {setup}, 1 thread",
            one_thread_ms,
            "ms",
            "one exact Dijkstra per robot",
            exact_ms,
            goal,
        ),
    ]
