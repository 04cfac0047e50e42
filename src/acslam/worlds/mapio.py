"""ROS map_server maps: a YAML description plus a PGM/PNG image.

Cells are stored as ROS ``OccupancyGrid`` values: -1 unknown, 0 free, 100 occupied.
Saving writes the trinary values map_saver writes (0 occupied, 254 free, 205 unknown) and
loading applies the map_server thresholds, so a save/load round trip is exact. Every
field of the YAML is checked, and a bad one is named (``map.yaml: occupied_thresh: ...``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from PIL import Image
from pydantic import BaseModel, ConfigDict, Field, field_validator

from acslam.config import FiniteFloat, PositiveFloat, Probability, ordered, validated
from acslam.errors import ConfigError
from acslam.files import atomic_path, open_image, read_yaml, write_yaml
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
    with atomic_path(pgm_path) as temporary:
        Image.fromarray(np.flipud(pixels), mode="L").save(temporary)
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
    write_yaml(yaml_path, description)
    return yaml_path, pgm_path


class MapDescription(BaseModel):
    """The fields of a map_server YAML, as map_server reads them. ``mode: raw`` (pixel
    values taken as occupancy) is not supported: thresholds would misread such a map."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    image: Annotated[str, Field(min_length=1)]
    mode: Literal["trinary", "scale"] = "trinary"
    resolution: PositiveFloat
    origin: tuple[FiniteFloat, FiniteFloat, FiniteFloat]
    negate: int = 0
    occupied_thresh: Probability = _OCCUPIED_THRESH
    free_thresh: Probability = _FREE_THRESH

    _thresholds = ordered(("free_thresh", "occupied_thresh", True))

    @field_validator("negate", mode="before")
    @classmethod
    def _flag(cls, value: Any) -> int:
        """map_server reads ``negate`` as an integer; a quoted "false" is not one."""
        if isinstance(value, bool) or value in (0, 1):
            return int(value)
        raise ValueError(f"must be 0 or 1, got {value!r}")


def read_map_description(yaml_path: Path) -> MapDescription:
    """The checked fields of a map_server YAML, or a ConfigError naming the field."""
    yaml_path = Path(yaml_path)
    data = read_yaml(yaml_path, "map file")
    if not isinstance(data, dict):
        raise ConfigError(yaml_path, "", "a map file must be a YAML mapping of its fields")
    description = validated(MapDescription, data, yaml_path)
    if description.origin[2] != 0.0:
        raise ConfigError(
            yaml_path, "origin[2]", "rotated maps (origin yaw != 0) are not supported"
        )
    return description


def _image_path(yaml_path: Path, description: MapDescription) -> Path:
    image_path = Path(description.image)
    return image_path if image_path.is_absolute() else Path(yaml_path).parent / image_path


def map_spec(yaml_path: Path) -> GridSpec:
    """The grid of a map_server map, from its YAML and its image's header alone (no pixels
    read): what a world of it would allocate."""
    description = read_map_description(yaml_path)
    with open_image(_image_path(yaml_path, description), f"map image of {yaml_path}") as image:
        cols, rows = image.size
    x0, y0, _ = description.origin
    return GridSpec(x0, y0, description.resolution, rows, cols)


def load_map(yaml_path: Path) -> tuple[np.ndarray, GridSpec]:
    """Read a map_server YAML + image; returns (OccupancyGrid values, grid spec)."""
    yaml_path = Path(yaml_path)
    description = read_map_description(yaml_path)
    with open_image(_image_path(yaml_path, description), f"map image of {yaml_path}") as image:
        grey = np.asarray(image.convert("L"), dtype=np.float64)

    occupancy = grey / 255.0 if description.negate else (255.0 - grey) / 255.0
    cells = np.full(grey.shape, UNKNOWN, dtype=np.int8)
    cells[occupancy > description.occupied_thresh] = OCCUPIED
    cells[occupancy < description.free_thresh] = FREE
    cells = np.flipud(cells).copy()
    x0, y0, _ = description.origin
    spec = GridSpec(x0, y0, description.resolution, *cells.shape)
    return cells, spec


def load_world(yaml_path: Path) -> World:
    """A map_server map as ground truth: unknown cells are treated as obstacles."""
    cells, spec = load_map(yaml_path)
    return World(name=Path(yaml_path).stem, spec=spec, occupied=cells != FREE)
