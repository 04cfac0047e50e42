"""Street maps from OpenStreetMap: roads of a local extract as free space.

Ways with a ``highway`` tag (optionally only the listed types) are projected to metres
with an equirectangular projection around the crop centre (accurate to far below 0.1 %
over a few kilometres), drawn as thick lines of ``road_width_m`` into a
``width_m x height_m`` window centred there, and only the largest connected road network
is kept. World coordinates are metres east/north of the crop centre.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import osmium
from scipy import ndimage

from acslam.config import OsmWorld
from acslam.errors import DataError
from acslam.grid import GridSpec
from acslam.worlds.world import World

EARTH_RADIUS_M = 6_371_008.8
"""Mean Earth radius (IUGG), the sphere haversine distances use."""
START_SPACING_M = 0.7
START_STEPS = 2
"""Start poses up to this many spacings either side of the road point nearest the centre."""
START_CLEARANCE_M = 0.3
_SUBPIXEL_BITS = 4


def project_lon_lat(lon_lat: np.ndarray, center_lat_lon: tuple[float, float]) -> np.ndarray:
    """(N, 2) ``[lon, lat]`` degrees -> (N, 2) ``[x east, y north]`` metres from the centre."""
    lat0, lon0 = center_lat_lon
    lon_lat = np.asarray(lon_lat, dtype=float)
    x = np.radians(lon_lat[:, 0] - lon0) * math.cos(math.radians(lat0)) * EARTH_RADIUS_M
    y = np.radians(lon_lat[:, 1] - lat0) * EARTH_RADIUS_M
    return np.column_stack([x, y])


def read_highways(path: Path, highway_types: list[str] | None) -> list[np.ndarray]:
    """Polylines ``[lon, lat]`` of the highway ways, split where a node has no location."""
    if not path.is_file():
        raise DataError(path, "OSM file not found")
    processor = (
        osmium.FileProcessor(str(path), osmium.osm.NODE | osmium.osm.WAY)
        .with_locations()
        .with_filter(osmium.filter.EntityFilter(osmium.osm.WAY))
        .with_filter(osmium.filter.KeyFilter("highway"))
    )
    wanted = set(highway_types) if highway_types is not None else None
    lines: list[np.ndarray] = []
    try:
        for way in processor:
            if wanted is not None and way.tags.get("highway") not in wanted:
                continue
            points: list[tuple[float, float]] = []
            for node in way.nodes:
                if node.location.valid():
                    points.append((node.location.lon, node.location.lat))
                    continue
                if len(points) >= 2:
                    lines.append(np.array(points))
                points = []
            if len(points) >= 2:
                lines.append(np.array(points))
    except RuntimeError as exc:  # libosmium reports parse and I/O errors this way
        raise DataError(path, f"cannot read OSM data: {exc}") from None
    return lines


def data_center(path: Path, lines: list[np.ndarray]) -> tuple[float, float]:
    """``(lat, lon)`` centre of the file's header bounds, else of the roads' nodes."""
    try:
        reader = osmium.io.Reader(str(path), osmium.osm.NOTHING)
        box = reader.header().box()
        reader.close()
    except RuntimeError as exc:
        raise DataError(path, f"cannot read OSM header: {exc}") from None
    if box.valid():
        low, high = box.bottom_left, box.top_right
        return ((low.lat + high.lat) / 2, (low.lon + high.lon) / 2)
    every = np.concatenate(lines)
    low, high = every.min(axis=0), every.max(axis=0)
    return ((low[1] + high[1]) / 2, (low[0] + high[0]) / 2)


def _nearest_arc(line: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(arc length, distance) of the point of polyline ``line`` nearest ``target``."""
    seg = np.diff(line, axis=0)
    length = np.linalg.norm(seg, axis=1)
    t = np.clip(np.einsum("ij,ij->i", target - line[:-1], seg) / np.maximum(length**2, 1e-12), 0, 1)
    dist = np.linalg.norm(line[:-1] + t[:, None] * seg - target, axis=1)
    k = int(np.argmin(dist))
    return float(length[:k].sum() + t[k] * length[k]), float(dist[k])


def _poses_along(line: np.ndarray, arc_lengths: np.ndarray) -> np.ndarray:
    """(K, 3) poses on a polyline at the given arc lengths, heading along the line."""
    seg = np.diff(line, axis=0)
    length = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(length)])
    k = np.clip(np.searchsorted(cum, arc_lengths, side="right") - 1, 0, len(seg) - 1)
    t = (arc_lengths - cum[k]) / np.maximum(length[k], 1e-12)
    xy = line[k] + t[:, None] * seg[k]
    theta = np.arctan2(seg[k, 1], seg[k, 0])
    return np.column_stack([xy, theta])


def osm_spec(cfg: OsmWorld) -> GridSpec:
    """The window of ``width_m`` x ``height_m`` around the crop centre."""
    res = cfg.resolution_m
    return GridSpec(
        -cfg.width_m / 2,
        -cfg.height_m / 2,
        res,
        round(cfg.height_m / res),
        round(cfg.width_m / res),
    )


def osm_world(cfg: OsmWorld) -> World:
    """Rasterise the roads around the crop centre; starts sit on the road nearest it."""
    path = Path(cfg.file)
    lines_deg = read_highways(path, cfg.highway_types)
    if not lines_deg:
        raise DataError(path, "no highway ways with node locations in the file")
    center = cfg.center_lat_lon or data_center(path, lines_deg)
    lines = [project_lon_lat(line, center) for line in lines_deg]

    res = cfg.resolution_m
    spec = osm_spec(cfg)
    reach = cfg.road_width_m
    in_window = [
        line
        for line in lines
        if line[:, 0].max() >= spec.origin_x_m - reach
        and line[:, 0].min() <= -spec.origin_x_m + reach
        and line[:, 1].max() >= spec.origin_y_m - reach
        and line[:, 1].min() <= -spec.origin_y_m + reach
    ]
    window = (
        f"{cfg.width_m:g} m x {cfg.height_m:g} m window around lat/lon "
        f"{center[0]:.6f}, {center[1]:.6f}"
    )
    if not in_window:
        raise DataError(path, f"no highway ways in the {window}")

    scale = (1 << _SUBPIXEL_BITS) / res
    pixels = [
        np.round(
            np.column_stack([line[:, 0] - spec.origin_x_m, line[:, 1] - spec.origin_y_m]) * scale
            - scale * res / 2
        )
        .astype(np.int32)
        .reshape(-1, 1, 2)
        for line in in_window
    ]
    canvas = np.zeros(spec.shape, dtype=np.uint8)
    thickness = max(1, round(cfg.road_width_m / res))
    cv2.polylines(
        canvas, pixels, False, 1, thickness=thickness, lineType=cv2.LINE_8, shift=_SUBPIXEL_BITS
    )
    labels, count = ndimage.label(canvas.astype(bool), structure=np.ones((3, 3), dtype=bool))
    if count == 0:
        raise DataError(path, f"no highway ways in the {window}")
    largest = np.argmax(np.bincount(labels.ravel())[1:]) + 1
    occupied = labels != largest
    world = World(name=f"osm-{path.name}", spec=spec, occupied=occupied)

    # Poses along the road nearest the centre, on its centre line, where a robot fits:
    # the unbroken run of fitting poses around the nearest point.
    steps = np.arange(-START_STEPS, START_STEPS + 1) * START_SPACING_M
    nearest = [_nearest_arc(line, np.zeros(2)) for line in in_window]
    for index in np.argsort([dist for _, dist in nearest], kind="stable"):
        line = in_window[index]
        total = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
        arcs = nearest[index][0] + steps
        poses = _poses_along(line, np.clip(arcs, 0.0, total))
        fits = (arcs >= 0) & (arcs <= total)
        fits &= np.array([world.clearance_at(x, y) >= START_CLEARANCE_M for x, y, _ in poses])
        if not fits[START_STEPS]:
            continue
        lo = START_STEPS - np.argmin(np.append(fits[START_STEPS::-1], False))
        hi = START_STEPS + np.argmin(np.append(fits[START_STEPS:], False))
        run = np.arange(lo + 1, hi)
        starts = poses[run[np.argsort(np.abs(steps[run]), kind="stable")]]
        break
    else:
        raise DataError(path, f"no road wide enough for a robot in the {window}")
    return World(name=world.name, spec=spec, occupied=occupied, default_starts=starts)
