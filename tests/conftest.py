"""Shared fixtures."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

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
