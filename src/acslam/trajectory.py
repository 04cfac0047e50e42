"""Planar trajectories in the TUM RGB-D text format.

One line per pose: ``timestamp tx ty tz qx qy qz qw``; planar poses have tz = 0 and a
rotation about z only, so ``theta = 2 * atan2(qz, qw)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from acslam.errors import DataError
from acslam.files import atomic_path


def write_tum(path: Path, stamps: np.ndarray, poses: np.ndarray) -> None:
    """Write (N,) stamps and (N, 3) ``[x, y, theta]`` poses as a TUM file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    half = 0.5 * poses[:, 2]
    zeros = np.zeros(len(poses))
    table = np.column_stack(
        [stamps, poses[:, 0], poses[:, 1], zeros, zeros, zeros, np.sin(half), np.cos(half)]
    )
    with atomic_path(path) as temporary:
        np.savetxt(temporary, table, fmt="%.9f", header="timestamp tx ty tz qx qy qz qw")


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file; returns (N,) stamps and (N, 3) planar poses."""
    path = Path(path)
    try:
        table = np.loadtxt(path, comments="#", ndmin=2)
    except (OSError, ValueError) as exc:
        raise DataError(path, f"not a TUM trajectory ({exc})") from None
    if table.shape[1] != 8 or not np.isfinite(table).all():
        raise DataError(path, "a TUM trajectory needs 8 finite numbers per line")
    theta = 2.0 * np.arctan2(table[:, 6], table[:, 7])
    theta = (theta + np.pi) % (2 * np.pi) - np.pi
    return table[:, 0], np.column_stack([table[:, 1], table[:, 2], theta])
