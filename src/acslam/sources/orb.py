"""ORB landmarks from RGB + registered depth (thesis §4.3, eqs. 4.1-4.2): the camera
front end that turns RGB-D frames into :class:`~acslam.messages.LandmarkObservations`.

Keypoints come from OpenCV's ORB on the grey image; each keypoint's depth (metres =
raw / ``depth_scale``) back-projects it with the pinhole model of eq. 4.1. Keypoints
outside the depth range (eq. 4.2), without depth (raw 0), or within ``border_px`` of the
image edge are dropped. Points come out in the camera's optical frame (x right, y down,
z forward) and go to the robot frame (x forward, y left, z up) through the camera mount.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from acslam.messages import LandmarkObservations

OPTICAL_TO_ROBOT = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Rotation of a camera mounted looking forward: optical z forward is robot x, optical
x right is robot -y, optical y down is robot -z."""


@dataclass(frozen=True)
class CameraMount:
    """Where the camera sits on the robot: rotation and translation (m) from its optical
    frame to the robot frame."""

    rotation: np.ndarray = field(default_factory=lambda: OPTICAL_TO_ROBOT.copy())
    translation_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def to_robot(self, points_optical: np.ndarray) -> np.ndarray:
        return np.asarray(points_optical) @ self.rotation.T + self.translation_m


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics (pixels) and the depth image's raw units per metre."""

    fx: float
    fy: float
    cx: float
    cy: float
    depth_scale: float = 5000.0


@dataclass(frozen=True)
class Features:
    """(N, 3) camera-frame points, (N, 2) pixel coordinates, (N, 32) ORB descriptors."""

    points: np.ndarray
    pixels: np.ndarray
    descriptors: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def back_project(pixels: np.ndarray, depth_m: np.ndarray, camera: CameraIntrinsics) -> np.ndarray:
    """Eq. 4.1: X = (u - cx) Z / fx, Y = (v - cy) Z / fy, Z = d."""
    z = np.asarray(depth_m, dtype=float)
    x = (pixels[:, 0] - camera.cx) * z / camera.fx
    y = (pixels[:, 1] - camera.cy) * z / camera.fy
    return np.column_stack([x, y, z])


def extract_features(
    rgb: np.ndarray,
    depth_raw: np.ndarray,
    camera: CameraIntrinsics,
    z_min_m: float = 0.3,
    z_max_m: float = 4.0,
    border_px: int = 20,
    max_features: int = 1000,
) -> Features:
    """ORB keypoints with valid depth -> 3D landmarks in the camera frame, descriptors kept."""
    if rgb.shape[:2] != depth_raw.shape[:2]:
        raise ValueError("rgb and depth must be registered images of the same size")
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if rgb.ndim == 3 else rgb
    orb = cv2.ORB_create(nfeatures=max_features)
    keypoints, descriptors = orb.detectAndCompute(grey, None)
    if not keypoints:
        return Features(np.zeros((0, 3)), np.zeros((0, 2)), np.zeros((0, 32), np.uint8))
    pixels = np.array([kp.pt for kp in keypoints])
    height, width = grey.shape
    cols = np.rint(pixels[:, 0]).astype(int).clip(0, width - 1)
    rows = np.rint(pixels[:, 1]).astype(int).clip(0, height - 1)
    depth_m = depth_raw[rows, cols].astype(float) / camera.depth_scale
    inside = (
        (pixels[:, 0] >= border_px)
        & (pixels[:, 0] < width - border_px)
        & (pixels[:, 1] >= border_px)
        & (pixels[:, 1] < height - border_px)
    )
    keep = inside & (depth_m > 0) & (depth_m >= z_min_m) & (depth_m <= z_max_m)
    points = back_project(pixels[keep], depth_m[keep], camera)
    return Features(points, pixels[keep], descriptors[keep])


def match(first: Features, second: Features, ratio: float = 0.75) -> np.ndarray:
    """(K, 2) index pairs (first, second) passing Lowe's ratio test on Hamming distance."""
    if len(first) == 0 or len(second) < 2:
        return np.zeros((0, 2), dtype=int)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    pairs = [
        (best.queryIdx, best.trainIdx)
        for best, second_best in (
            m for m in matcher.knnMatch(first.descriptors, second.descriptors, k=2) if len(m) == 2
        )
        if best.distance < ratio * second_best.distance
    ]
    return np.array(pairs, dtype=int).reshape(-1, 2)


def landmark_observations(
    features: Features, robot_id: int, stamp: float, mount: CameraMount | None = None
) -> LandmarkObservations:
    """The frame's features as the robot's landmark message: points in the robot frame,
    descriptors kept for the association."""
    mount = mount or CameraMount()
    return LandmarkObservations(
        robot_id, stamp, mount.to_robot(features.points), descriptors=features.descriptors
    )
