"""Ground-truth world generators: connectivity, sizes, reproducibility, file errors."""

from __future__ import annotations

import bz2
import math
from collections.abc import Callable
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from acslam.config import (
    DungeonWorld,
    FloorplanWorld,
    LandmarkConfig,
    MapFileWorld,
    OsmWorld,
    ThesisWorld,
    VineyardWorld,
)
from acslam.errors import DataError
from acslam.worlds.generators import build_world
from acslam.worlds.landmarks import place_landmarks
from acslam.worlds.osm import EARTH_RADIUS_M, project_lon_lat
from acslam.worlds.thesis import WALL_M, rect_cells, thesis_layout
from acslam.worlds.vineyard import stamp_discs
from acslam.worlds.world import World

ROBOT_RADIUS_M = 0.105
EIGHT = np.ones((3, 3), dtype=bool)
OSM = "datasets/osm"
HELSINKI = f"{OSM}/Helsinki.osm.pbf"
PLANET = f"{OSM}/planet_10.068_48.135_10.071_48.137.osm"
FLOORPLANS = "datasets/floorplans_ipa"
PLANET_CENTER = (48.1357, 10.0703)
"""A point amid the planet extract's roads (its own centre has few)."""


@cache
def thesis(experiment: int) -> World:
    return build_world(ThesisWorld(generator="thesis", experiment=experiment), seed=0)


@cache
def dungeon(size_m: float, rooms: int, seed: int = 0) -> World:
    cfg = DungeonWorld(generator="dungeon", width_m=size_m, height_m=size_m, room_count=rooms)
    return build_world(cfg, seed=seed)


def vineyard(seed: int = 0, **fields: float) -> World:
    return build_world(VineyardWorld(generator="vineyard", **fields), seed=seed)


def osm(path: Path, **fields: object) -> World:
    return build_world(OsmWorld(generator="osm", file=path, **fields), seed=0)


def floorplan(path: Path) -> World:
    return build_world(FloorplanWorld(generator="floorplan", file=path), seed=0)


def cell(world: World, xy: np.ndarray) -> tuple[int, int]:
    row, col = world.spec.world_to_cell(xy[:2])[0]
    return int(row), int(col)


def assert_starts_connected(world: World, min_starts: int, min_clearance_m: float) -> None:
    """All starts lie in the free space a robot can sweep from the first one, and no two
    robots standing on them overlap."""
    starts = world.default_starts
    assert starts.shape[1] == 3 and len(starts) >= min_starts
    gaps_m = np.linalg.norm(starts[:, None, :2] - starts[None, :, :2], axis=2)
    assert gaps_m[~np.eye(len(starts), dtype=bool)].min() > 2 * ROBOT_RADIUS_M
    reach = world.reachable_free(starts[0, 0], starts[0, 1], ROBOT_RADIUS_M)
    for pose in starts:
        assert reach[cell(world, pose)], f"start {pose} not reachable from {starts[0]}"
        assert world.clearance_at(pose[0], pose[1]) >= min_clearance_m


WORLDS: dict[str, tuple[Callable[[Callable[[str], Path]], World], int, float]] = {
    **{f"thesis-exp{e}": ((lambda _, e=e: thesis(e)), 3, 0.3) for e in range(1, 6)},
    "vineyard": (lambda _: vineyard(), 3, ROBOT_RADIUS_M),
    "vineyard-40": (lambda _: vineyard(row_count=14, row_length_m=30.0), 10, ROBOT_RADIUS_M),
    "dungeon-20": (lambda _: dungeon(20.0, 8), 10, 0.3),
    "dungeon-40": (lambda _: dungeon(40.0, 16), 10, 0.3),
    "osm-helsinki": (lambda d: osm(d(HELSINKI), width_m=300.0, height_m=300.0), 3, 0.3),
    "osm-planet": (
        lambda d: osm(d(PLANET), center_lat_lon=PLANET_CENTER, width_m=120.0, height_m=120.0),
        3,
        0.3,
    ),
    "floorplan-lab_ipa": (lambda d: floorplan(d(f"{FLOORPLANS}/lab_ipa.png")), 3, 0.3),
    # 10 robots: the floor plans' lattice beyond the first five starts.
    "floorplan-office_b": (lambda d: floorplan(d(f"{FLOORPLANS}/office_b.png")), 10, 0.3),
}


@pytest.mark.parametrize("name", list(WORLDS))
def test_starts_share_one_robot_passable_component(
    name: str, shared_dataset: Callable[[str], Path]
) -> None:
    make, min_starts, min_clearance = WORLDS[name]
    assert_starts_connected(make(shared_dataset), min_starts, min_clearance)


# --------------------------------------------------------------------------- thesis


@pytest.mark.parametrize(("experiment", "area_m2"), [(1, 65), (2, 65), (3, 65), (4, 65), (5, 100)])
def test_thesis_grid_and_reachable_area(experiment: int, area_m2: float) -> None:
    world = thesis(experiment)
    assert world.spec.shape == (800, 800) and world.spec.resolution_m == 0.05
    assert len(world.default_starts) == 3
    x, y = world.default_starts[0, :2]
    reachable = world.reachable_free(x, y, ROBOT_RADIUS_M).sum() * 0.05**2
    assert abs(reachable - area_m2) <= 0.2 * area_m2
    # the explorable area lies around the grid centre
    rows, cols = np.nonzero(world.free)
    assert abs(rows.mean() - 400) < 120 and abs(cols.mean() - 400) < 120


def ring_gap_count(world: World, start_area: tuple[float, float, float, float]) -> int:
    """Free gaps in the wall-thick ring around the start area (its openings)."""
    res = world.spec.resolution_m
    inner = np.zeros(world.spec.shape, dtype=bool)
    inner[rect_cells(start_area, res)] = True
    assert world.free[inner].all(), "start area is not all free"
    wall_cells = round(WALL_M / res)
    ring = ndimage.binary_dilation(inner, EIGHT, iterations=wall_cells) & ~inner
    _, count = ndimage.label(ring & world.free, EIGHT)
    return count


@pytest.mark.parametrize(("experiment", "openings"), [(1, 1), (2, 3), (3, 4), (4, 5)])
def test_thesis_initial_frontiers(experiment: int, openings: int) -> None:
    world, layout = thesis(experiment), thesis_layout(experiment)
    res = world.spec.resolution_m
    assert len(layout.start_openings) == openings
    # counted from the grid alone: free gaps through the start area's wall
    assert ring_gap_count(world, layout.start_area) == openings
    x0, y0, x1, y1 = layout.start_area
    assert all(x0 < x < x1 and y0 < y < y1 for x, y, _ in world.default_starts)
    for rect in layout.start_openings:
        rows, cols = rect_cells(rect, res)
        assert world.free[rows, cols].all()
        # thin across the wall: free on both sides, wall at both ends along it
        if rows.stop - rows.start < cols.stop - cols.start:
            across = world.free[[rows.start - 1, rows.stop], cols]
            along = world.occupied[rows, [cols.start - 1, cols.stop]]
        else:
            across = world.free[rows, [cols.start - 1, cols.stop]]
            along = world.occupied[[rows.start - 1, rows.stop], cols]
        assert across.all() and along.all(), f"opening {rect} is not a gap in a wall"


# --------------------------------------------------------------------------- seeds


@pytest.mark.parametrize(
    "make",
    [
        lambda seed: vineyard(seed=seed),
        lambda seed: dungeon(20.0, 8, seed=seed),
    ],
    ids=["vineyard", "dungeon"],
)
def test_seed_reproducibility(make: Callable[[int], World]) -> None:
    a, b, c = make(3), make(3), make(4)
    assert np.array_equal(a.occupied, b.occupied)
    assert np.array_equal(a.default_starts, b.default_starts)
    assert not np.array_equal(a.occupied, c.occupied)


@pytest.mark.parametrize("seed", range(1, 7))
def test_dungeon_free_space_connected_over_seeds(seed: int) -> None:
    world = dungeon(20.0, 8, seed=seed)
    assert_starts_connected(world, 10, 0.3)
    x, y = world.default_starts[0, :2]
    reach = world.reachable_free(x, y, ROBOT_RADIUS_M)
    # a robot sweeps almost all free space (only corners and door jambs escape it)
    assert reach.sum() > 0.97 * world.free.sum()


def test_dungeon_40_has_walls_doors_and_many_starts() -> None:
    world = dungeon(40.0, 16)
    assert world.spec.shape == (800, 800)
    assert world.occupied[0].all() and world.occupied[-1].all()
    assert world.occupied[:, 0].all() and world.occupied[:, -1].all()
    # one free space, with many rooms: far more free area than any single room
    _, count = ndimage.label(world.free, EIGHT)
    assert count == 1
    assert world.free_area_m2() > 8 * 6.0**2
    assert len(world.default_starts) >= 10


# --------------------------------------------------------------------------- vineyard


def field_interior(world: World) -> np.ndarray:
    """The occupied cells inside the fence (the plants): the fence is the biggest blob."""
    labels, _ = ndimage.label(world.occupied, EIGHT)
    fence = labels == np.argmax(np.bincount(labels.ravel())[1:]) + 1
    return world.occupied & ndimage.binary_fill_holes(fence) & ~fence


@pytest.mark.parametrize("row_count", [1, 6, 9])
def test_vineyard_row_count(row_count: int) -> None:
    world = vineyard(seed=1, row_count=row_count)
    plants = field_interior(world)
    _, bands = ndimage.label(plants.any(axis=1))
    assert bands == row_count


def test_vineyard_plant_count_without_gaps() -> None:
    separate = {"plant_spacing_m": 0.9, "plant_radius_m": 0.15}
    world = vineyard(gap_probability=0.0, jitter_m=0.0, **separate)
    _, plants = ndimage.label(field_interior(world), EIGHT)
    # 6 rows of plants at 0, 0.9, ..., 13.5 m along a 14 m row: 16 per row
    assert plants == 6 * 16
    with_gaps = vineyard(gap_probability=0.5, jitter_m=0.0, **separate)
    _, fewer = ndimage.label(field_interior(with_gaps), EIGHT)
    assert 20 < fewer < 80


def test_vineyard_plants_are_round_obstacles_for_the_lidar() -> None:
    world = vineyard(gap_probability=0.0, jitter_m=0.0, plant_spacing_m=0.9)
    assert len(world.discs) == 6 * 16 and np.all(world.discs[:, 2] == 0.2)
    plants = world.occupied & ~world.lidar_grid
    # The grid the LiDAR casts against is the fence alone; the plants' cells are exactly
    # their discs stamped.
    stamped = np.zeros_like(world.occupied)
    stamp_discs(stamped, world.spec, world.discs[:, :2], 0.2)
    assert np.array_equal(plants, stamped & ~world.lidar_grid)
    assert not (world.lidar_grid & stamped).any()


def test_vineyard_starts_face_the_rows_in_the_headland() -> None:
    world = vineyard()
    starts = world.default_starts
    assert np.all(starts[:, 0] < 0) and np.all(starts[:, 2] == 0.0)
    assert np.allclose(np.diff(np.sort(starts[:3, 1])), 0.6)


# --------------------------------------------------------------------------- osm


def assert_connected_roads(world: World) -> None:
    fraction = world.free.mean()
    assert 0.05 < fraction < 0.60
    _, count = ndimage.label(world.free, EIGHT)
    assert count == 1


def test_osm_helsinki_pbf(shared_dataset: Callable[[str], Path]) -> None:
    world = osm(shared_dataset(HELSINKI), width_m=300.0, height_m=300.0)
    assert world.spec.shape == (1200, 1200)
    assert_connected_roads(world)


def test_osm_xml_and_bz2_agree(shared_dataset: Callable[[str], Path], tmp_path: Path) -> None:
    xml = shared_dataset(PLANET)
    packed = tmp_path / "planet.osm.bz2"
    packed.write_bytes(bz2.compress(xml.read_bytes()))
    fields = {"center_lat_lon": PLANET_CENTER, "width_m": 120.0, "height_m": 120.0}
    plain, compressed = osm(xml, **fields), osm(packed, **fields)
    assert_connected_roads(plain)
    assert np.array_equal(plain.occupied, compressed.occupied)
    assert np.array_equal(plain.default_starts, compressed.default_starts)


def haversine_m(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    p1, p2 = math.radians(lat1), math.radians(lat2)
    dp, dl = p2 - p1, math.radians(lon2 - lon1)
    h = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2 * EARTH_RADIUS_M * math.asin(math.sqrt(h))


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ((60.1642, 24.9352), (60.1791, 24.9534)),  # corners of the Helsinki extract
        ((48.1350, 10.0680), (48.1370, 10.0710)),  # corners of the planet extract
        ((48.1360, 10.0600), (48.1360, 10.0800)),  # 1.5 km due east
    ],
)
def test_osm_projection_matches_haversine(a: tuple[float, float], b: tuple[float, float]) -> None:
    center = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
    xy = project_lon_lat(np.array([[a[1], a[0]], [b[1], b[0]]]), center)
    projected = float(np.linalg.norm(xy[1] - xy[0]))
    assert projected == pytest.approx(haversine_m(*a, *b), rel=0.005)
    assert np.sign(xy[1] - xy[0]).tolist() == np.sign([b[1] - a[1], b[0] - a[0]]).tolist()


def test_osm_default_center_is_the_file_bounds(shared_dataset: Callable[[str], Path]) -> None:
    path = shared_dataset(PLANET)
    auto = osm(path, width_m=120.0, height_m=120.0)
    explicit = osm(path, center_lat_lon=(48.136, 10.0695), width_m=120.0, height_m=120.0)
    assert np.array_equal(auto.occupied, explicit.occupied)


# --------------------------------------------------------------------------- floorplans


@pytest.mark.parametrize("name", ["lab_ipa", "office_b"])
def test_floorplan_ipa(name: str, shared_dataset: Callable[[str], Path]) -> None:
    path = shared_dataset(f"{FLOORPLANS}/{name}.png")
    world = floorplan(path)
    with Image.open(path) as image:
        width, height = image.size
        light = np.asarray(image.convert("L")) >= 250
    assert world.spec.shape == (height, width)
    # the kept free space is one component, all light in the (flipped) image
    assert np.all(np.flipud(light)[world.free])
    assert not np.all(light[world.free])
    _, count = ndimage.label(world.free, EIGHT)
    assert count == 1 and world.free.sum() > 0.5 * light.sum()


@pytest.mark.parametrize("mode", ["L", "LA", "RGB", "RGBA"])
def test_floorplan_flips_rows_in_every_mode(mode: str, tmp_path: Path) -> None:
    grey = np.zeros((40, 60), dtype=np.uint8)
    grey[1:16, 2:40] = 255  # a 1.5 m x 3.8 m room in the image's top part
    image = Image.fromarray(grey, mode="L").convert(mode)
    path = tmp_path / f"plan_{mode}.png"
    image.save(path)
    world = build_world(FloorplanWorld(generator="floorplan", file=path, resolution_m=0.1), seed=0)
    assert world.spec.shape == (40, 60) and world.spec.origin_x_m == 0.0
    assert world.free.sum() == 15 * 38
    assert world.free[39 - 1, 2] and world.free[39 - 15, 39]  # top image rows -> top grid rows
    assert not world.free[:24].any()
    assert_starts_connected(world, 3, 0.0)


def test_floorplan_starts_are_the_plus_then_the_lattice_with_room(tmp_path: Path) -> None:
    grey = np.zeros((85, 85), dtype=np.uint8)
    grey[2:83, 2:83] = 255  # a 4.05 m square room at 0.05 m: its centre cell is the most open
    path = tmp_path / "room.png"
    Image.fromarray(grey, mode="L").save(path)
    world = build_world(FloorplanWorld(generator="floorplan", file=path), seed=0)
    starts = world.default_starts
    assert np.allclose(starts[0, :2], [2.125, 2.125])
    offsets = np.round((starts[:, :2] - starts[0, :2]) / 0.6).astype(int)
    assert np.allclose(starts[:, :2] - starts[0, :2], offsets * 0.6)
    assert offsets[:5].tolist() == [[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]]
    # Lattice points 2 spacings out keep 2.025 - 1.2 m from the walls; 3 out, only 0.225 m.
    assert sorted(map(tuple, offsets.tolist())) == [
        (i, j) for i in range(-2, 3) for j in range(-2, 3)
    ]
    assert np.all(np.diff(np.hypot(*offsets[5:].T)) >= 0)


# --------------------------------------------------------------------------- landmarks


def test_landmarks_count_placement_and_seed() -> None:
    world = thesis(2)
    cfg = LandmarkConfig(density_per_m2=0.5, max_obstacle_distance_m=0.3)
    points = place_landmarks(world, cfg, np.random.default_rng(5))
    assert points.shape == (round(0.5 * world.free_area_m2()), 3)
    cells = world.spec.world_to_cell(points[:, :2])
    assert world.free[cells[:, 0], cells[:, 1]].all()
    assert np.all(world.clearance_m[cells[:, 0], cells[:, 1]] <= 0.3 + 0.05)
    assert np.all((points[:, 2] >= cfg.z_min_m) & (points[:, 2] <= cfg.z_max_m))
    again = place_landmarks(world, cfg, np.random.default_rng(5))
    assert np.array_equal(points, again)
    other = place_landmarks(world, cfg, np.random.default_rng(6))
    assert not np.array_equal(points, other)


def test_landmarks_within_reachable_mask() -> None:
    world = thesis(5)
    x, y = world.default_starts[0, :2]
    reachable = world.reachable_free(x, y, ROBOT_RADIUS_M)
    lab = np.zeros_like(reachable)
    lab[rect_cells(thesis_layout(5).start_area, world.spec.resolution_m)] = True
    cfg = LandmarkConfig(density_per_m2=2.0, max_obstacle_distance_m=0.5)
    points = place_landmarks(world, cfg, np.random.default_rng(0), reachable=lab & reachable)
    area = (lab & reachable).sum() * world.spec.resolution_m**2
    assert len(points) == round(2.0 * area)
    cells = world.spec.world_to_cell(points[:, :2])
    assert lab[cells[:, 0], cells[:, 1]].all()


# --------------------------------------------------------------------------- dispatch


def test_build_world_loads_map_files(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from acslam.worlds import mapio

    stub = thesis(1)
    seen: list[Path] = []
    monkeypatch.setattr(mapio, "load_world", lambda path: seen.append(path) or stub)
    cfg = MapFileWorld(generator="map_file", file=tmp_path / "lab.yaml")
    assert build_world(cfg, seed=0) is stub
    assert seen == [tmp_path / "lab.yaml"]


def test_build_world_thesis_ignores_seed() -> None:
    cfg = ThesisWorld(generator="thesis", experiment=4)
    assert np.array_equal(build_world(cfg, 1).occupied, build_world(cfg, 2).occupied)


# --------------------------------------------------------------------------- bad files


def expect_data_error(path: Path, make: Callable[[], World]) -> None:
    with pytest.raises(DataError) as info:
        make()
    assert str(path) in str(info.value)


def test_bad_floorplan_files(tmp_path: Path) -> None:
    missing = tmp_path / "missing.png"
    expect_data_error(missing, lambda: floorplan(missing))
    text = tmp_path / "notes.png"
    text.write_text("not an image\n")
    expect_data_error(text, lambda: floorplan(text))


def test_bad_osm_files(tmp_path: Path, shared_dataset: Callable[[str], Path]) -> None:
    missing = tmp_path / "missing.osm"
    expect_data_error(missing, lambda: osm(missing))
    garbage = tmp_path / "garbage.osm"
    garbage.write_text("<osm><node id='1' lat=oops")
    expect_data_error(garbage, lambda: osm(garbage))
    bad_pbf = tmp_path / "garbage.osm.pbf"
    bad_pbf.write_bytes(b"\x00\x01 not a pbf" * 20)
    expect_data_error(bad_pbf, lambda: osm(bad_pbf))
    planet = shared_dataset(PLANET)
    expect_data_error(planet, lambda: osm(planet, center_lat_lon=(0.0, 0.0)))
    only_motorways = {"highway_types": ["motorway"]}
    expect_data_error(planet, lambda: osm(planet, **only_motorways))
