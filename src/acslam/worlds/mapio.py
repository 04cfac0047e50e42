"""ROS map_server maps: a YAML description plus a PGM/PNG image.

Cells are stored as ROS ``OccupancyGrid`` values: -1 unknown, 0 free, 100 occupied.
Saving writes the trinary values map_saver writes (0 occupied, 254 free, 205 unknown) and
loading applies the map_server thresholds, so a save/load round trip is exact.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, UnidentifiedImageError

from acslam.errors import DataError
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from acslam.worlds.world import World

_PIXEL = {OCCUPIED: 0, FREE: 254, UNKNOWN: 205}
_OCCUPIED_THRESH = 0.65
_FREE_THRESH = 0.196


def world_cells(world: World) -> np.ndarray:
    """The world as OccupancyGrid values (ground truth has no unknown cells)."""
    return np.where(world.occupied, OCCUPIED, FREE).astype(np.int8)


def save_map(stem: Path, cells: np.ndarray, spec: GridSpec) -> tuple[Path, Path]:
    """Write ``stem.yaml`` and ``stem.pgm``; returns both paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    pixels = np.full(cells.shape, _PIXEL[UNKNOWN], dtype=np.uint8)
    pixels[cells == FREE] = _PIXEL[FREE]
    pixels[cells == OCCUPIED] = _PIXEL[OCCUPIED]
    pgm_path = stem.with_suffix(".pgm")
    Image.fromarray(np.flipud(pixels), mode="L").save(pgm_path)
    yaml_path = stem.with_suffix(".yaml")
    description = {
        "image": pgm_path.name,
        "mode": "trinary",
        "resolution": float(spec.resolution_m),
        "origin": [float(spec.origin_x_m), float(spec.origin_y_m), 0.0],
        "negate": 0,
        "occupied_thresh": _OCCUPIED_THRESH,
        "free_thresh": _FREE_THRESH,
    }
    yaml_path.write_text(yaml.safe_dump(description, sort_keys=False), encoding="utf-8")
    return yaml_path, pgm_path


def _number(description: dict, key: str, path: Path) -> float:
    value = description.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise DataError(path, f"field {key!r} must be a finite number, got {value!r}")
    return float(value)


def load_map(yaml_path: Path) -> tuple[np.ndarray, GridSpec]:
    """Read a map_server YAML + image; returns (OccupancyGrid values, grid spec)."""
    yaml_path = Path(yaml_path)
    if not yaml_path.is_file():
        raise DataError(yaml_path, "map file not found")
    try:
        description = yaml.safe_load(yaml_path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise DataError(yaml_path, f"not a valid map YAML ({type(exc).__name__})") from None
    if not isinstance(description, dict) or "image" not in description:
        raise DataError(yaml_path, "map YAML must be a mapping with an 'image' field")
    resolution = _number(description, "resolution", yaml_path)
    if resolution <= 0:
        raise DataError(yaml_path, f"field 'resolution' must be > 0, got {resolution}")
    origin = description.get("origin")
    if not (isinstance(origin, list) and len(origin) == 3):
        raise DataError(yaml_path, "field 'origin' must be a list [x, y, yaw]")
    origin_xy_yaw = [_number({"origin": v}, "origin", yaml_path) for v in origin]
    if origin_xy_yaw[2] != 0.0:
        raise DataError(yaml_path, "rotated maps (origin yaw != 0) are not supported")
    occupied_thresh = float(description.get("occupied_thresh", _OCCUPIED_THRESH))
    free_thresh = float(description.get("free_thresh", _FREE_THRESH))
    negate = bool(description.get("negate", 0))

    image_path = Path(str(description["image"]))
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    try:
        with Image.open(image_path) as image:
            grey = np.asarray(image.convert("L"), dtype=np.float64)
    except FileNotFoundError:
        raise DataError(image_path, f"map image named by {yaml_path} not found") from None
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise DataError(image_path, f"map image cannot be read ({exc})") from None

    occupancy = grey / 255.0 if negate else (255.0 - grey) / 255.0
    cells = np.full(grey.shape, UNKNOWN, dtype=np.int8)
    cells[occupancy > occupied_thresh] = OCCUPIED
    cells[occupancy < free_thresh] = FREE
    cells = np.flipud(cells).copy()
    spec = GridSpec(origin_xy_yaw[0], origin_xy_yaw[1], resolution, *cells.shape)
    return cells, spec


def load_world(yaml_path: Path) -> World:
    """A map_server map as ground truth: unknown cells are treated as obstacles."""
    cells, spec = load_map(yaml_path)
    return World(name=Path(yaml_path).stem, spec=spec, occupied=cells != FREE)
