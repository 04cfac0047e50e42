"""TUM RGB-D frames: a colour image, its registered depth image and the camera's
ground-truth pose.

The layout read is one frame per name ``X`` in a folder: ``img_X.png`` (8-bit colour),
``dep_X.png`` (16-bit depth, raw / 5000 = metres, 0 = no data) and ``pose_X.txt`` (one
line ``tx ty tz qx qy qz qw``: camera to world, the TUM ground-truth convention).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from acslam.errors import DataError
from acslam.sources.orb import CameraIntrinsics

FREIBURG1 = CameraIntrinsics(fx=517.3, fy=516.5, cx=318.6, cy=255.3, depth_scale=5000.0)
"""The fr1 Kinect's colour intrinsics (TUM RGB-D documentation); depth is registered."""


@dataclass(frozen=True)
class RgbdFrame:
    """``rgb`` (H, W, 3) uint8, ``depth_raw`` (H, W) uint16 and the 4x4 camera-to-world
    ground-truth pose (optical frame: x right, y down, z forward)."""

    rgb: np.ndarray
    depth_raw: np.ndarray
    camera_to_world: np.ndarray


def _image(path: Path, flags: int) -> np.ndarray:
    if not path.is_file():
        raise DataError(path, "file not found")
    image = cv2.imread(str(path), flags)
    if image is None:
        raise DataError(path, "not a readable image")
    return image


def read_frame(folder: str | Path, name: str) -> RgbdFrame:
    """The frame ``name`` of ``folder`` (e.g. ``prev`` for img_prev.png ...)."""
    folder = Path(folder)
    rgb = cv2.cvtColor(_image(folder / f"img_{name}.png", cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    depth = _image(folder / f"dep_{name}.png", cv2.IMREAD_UNCHANGED)
    if depth.dtype != np.uint16 or depth.shape != rgb.shape[:2]:
        raise DataError(folder / f"dep_{name}.png", "depth must be 16-bit, registered to img")
    pose_path = folder / f"pose_{name}.txt"
    try:
        values = np.loadtxt(pose_path, ndmin=1)
    except (OSError, ValueError) as exc:
        raise DataError(pose_path, f"cannot read pose ({exc})") from None
    if values.shape != (7,) or not np.isfinite(values).all():
        raise DataError(pose_path, "a pose is one line of 7 finite numbers: t (3), q (4)")
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_quat(values[3:]).as_matrix()
    pose[:3, 3] = values[:3]
    return RgbdFrame(rgb, depth, pose)
