"""ROS map_server maps: exact round trips, the thresholds, and clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from acslam.errors import AcslamError, ConfigError
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from acslam.worlds.mapio import load_map, load_world, save_map


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    cells = rng.choice(np.array([UNKNOWN, FREE, OCCUPIED], dtype=np.int8), size=(37, 53))
    spec = GridSpec(-3.125, 7.3, 0.05, 37, 53)
    yaml_path, pgm_path = save_map(tmp_path / "m", cells, spec)
    assert pgm_path.read_bytes().startswith(b"P5")
    loaded, loaded_spec = load_map(yaml_path)
    assert loaded_spec == spec
    assert loaded.dtype == np.int8
    assert (loaded == cells).all()


def test_rows_are_flipped_to_y_up(tmp_path: Path) -> None:
    cells = np.full((4, 5), FREE, dtype=np.int8)
    cells[3, 0] = OCCUPIED  # top-left in the world (largest y, smallest x)
    save_map(tmp_path / "m", cells, GridSpec(0.0, 0.0, 1.0, 4, 5))
    pixels = np.asarray(Image.open(tmp_path / "m.pgm"))
    assert pixels[0, 0] == 0 and pixels[3, 0] == 254  # image row 0 is the top


def test_thresholds_and_negate(tmp_path: Path) -> None:
    # Grey 0 -> p=1 occupied, 100 -> p=0.61 unknown, 230 -> p=0.098 free (negate 0).
    Image.fromarray(np.array([[0, 100, 230]], dtype=np.uint8)).save(tmp_path / "g.png")
    (tmp_path / "g.yaml").write_text(
        "image: g.png\nresolution: 0.1\norigin: [1.0, 2.0, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    cells, spec = load_map(tmp_path / "g.yaml")
    assert cells.tolist() == [[OCCUPIED, UNKNOWN, FREE]]
    assert (spec.origin_x_m, spec.origin_y_m, spec.resolution_m) == (1.0, 2.0, 0.1)
    (tmp_path / "g.yaml").write_text(
        "image: g.png\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    cells, _ = load_map(tmp_path / "g.yaml")
    assert cells.tolist() == [[FREE, UNKNOWN, OCCUPIED]]
    world = load_world(tmp_path / "g.yaml")
    assert world.occupied.tolist() == [[False, True, True]]  # unknown counts as obstacle


@pytest.mark.parametrize(
    ("yaml_text", "image_bytes", "problem"),
    [
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", b"not an image", "cannot be read"),
        ("image: absent.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n", None, "not found"),
        ("image: m.pgm\nresolution: -1\norigin: [0, 0, 0]\n", None, "resolution: .* greater"),
        ("image: m.pgm\nresolution: x\norigin: [0, 0, 0]\n", None, "resolution: .* number"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0]\n", None, r"origin\[2\]: .*required"),
        ("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0.5]\n", None, "rotated maps"),
        ("resolution: 0.05\n", None, "image: Field required"),
        ("image: [unclosed\n", None, "invalid YAML at line 2"),
    ],
)
def test_corrupt_maps_name_the_file(
    tmp_path: Path, yaml_text: str, image_bytes: bytes | None, problem: str
) -> None:
    (tmp_path / "m.yaml").write_text(yaml_text)
    if image_bytes is not None:
        (tmp_path / "m.pgm").write_bytes(image_bytes)
    with pytest.raises(AcslamError, match=problem) as info:
        load_map(tmp_path / "m.yaml")
    assert str(tmp_path) in str(info.value)


def test_missing_yaml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="map file not found"):
        load_map(tmp_path / "none.yaml")
