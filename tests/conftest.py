"""Shared fixtures."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from acslam.grid import FREE, OCCUPIED, GridSpec
from acslam.worlds.mapio import save_map

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED = REPO_ROOT.parent / "shared"
"""The ``shared`` folder beside the repository root, holding the public datasets."""


@pytest.fixture
def shared_dataset() -> Callable[[str], Path]:
    """``shared_dataset("datasets/osm/x.osm")``: the file's path, or skip if absent."""

    def locate(relpath: str) -> Path:
        path = SHARED / relpath
        if not path.exists():
            pytest.skip(f"shared dataset not found: {path}")
        return path

    return locate


# A tiny scenario (two 5 m x 6 m rooms joined by a door) that three robots explore in
# about 35 s.
TINY_SCENARIO = """name: tiny
seed: 3
world: {generator: map_file, file: tiny.yaml}
robots:
  count: 3
  starts: [[1.0, 1.5, 0.0], [1.0, 3.0, 0.0], [1.0, 4.5, 0.0]]
  max_v_mps: 0.4
sim: {max_time_s: 120}
"""


@pytest.fixture(scope="session")
def tiny_scenario(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("tiny")
    occupied = np.zeros((120, 200), dtype=bool)
    occupied[:3], occupied[-3:], occupied[:, :3], occupied[:, -3:] = True, True, True, True
    occupied[:, 98:102] = True
    occupied[50:70, 98:102] = False  # the 1 m door
    occupied[20:24, 130:180] = True  # a shelf in the second room
    cells = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    save_map(folder / "tiny", cells, GridSpec(0.0, 0.0, 0.05, 120, 200))
    path = folder / "scenario.yaml"
    path.write_text(TINY_SCENARIO)
    return path


SHORT_RUN_S = 6.0
"""Simulated seconds of the shared short run: stopped by its time limit mid-exploration."""


class ShortRun(NamedTuple):
    folder: Path
    stdout: str
    command: list[str]


@pytest.fixture(scope="session")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> ShortRun:
    """``acslam run`` of the default scenario for a few simulated seconds, as a user starts
    it, its output piped: a complete run folder (metrics, figures, report) in ~5 s."""
    folder = tmp_path_factory.mktemp("short_run") / "run"
    arguments = ["run", "--max-time", f"{SHORT_RUN_S:g}", "--out", str(folder)]
    done = subprocess.run(
        [sys.executable, "-m", "acslam.cli", *arguments],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return ShortRun(folder, done.stdout, ["acslam", *arguments])
