"""Planar geometry helpers on plain floats and arrays (poses are ``[x, y, theta]``)."""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(angle: float) -> float:
    """Wrap an angle in radians to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def wrap_angles(angles: np.ndarray) -> np.ndarray:
    """Vectorised :func:`wrap_angle`."""
    return (np.asarray(angles) + np.pi) % (2.0 * np.pi) - np.pi


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SE(2) composition a * b: the pose b given in a's frame, expressed in the world."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array(
        [a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap_angle(a[2] + b[2])]
    )


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SE(2) relative pose a^-1 * b: b expressed in the frame of a."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[2] - a[2])])


def between_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`between` row by row of two (N, 3) pose arrays: each ``b[k]`` in the frame
    of ``a[k]``."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, wrap_angles(b[:, 2] - a[:, 2])])


def compose_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`compose` row by row of two (N, 3) pose arrays."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack(
        [
            a[:, 0] + c * b[:, 0] - s * b[:, 1],
            a[:, 1] + s * b[:, 0] + c * b[:, 1],
            wrap_angles(a[:, 2] + b[:, 2]),
        ]
    )


def transform_points(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map (N, 2) points from the frame of ``pose`` to the world frame."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])
    return points @ rot.T + pose[:2]


def beam_ends(pose: np.ndarray, angles: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """(N, 2) where beams at ``angles`` (rad, sensor frame) of ``ranges`` (m) end, seen
    from the sensor ``pose``; a beam of infinite range ends at infinity (or NaN on an
    axis it does not move along)."""
    headings = np.asarray(angles) + pose[2]
    with np.errstate(invalid="ignore"):
        return pose[:2] + np.asarray(ranges)[:, None] * np.column_stack(
            [np.cos(headings), np.sin(headings)]
        )


def fit_rigid(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The pose ``[x, y, theta]`` whose :func:`transform_points` lays the (N, 2) ``source``
    points closest to their ``target`` points in least squares (Umeyama 1991 without
    scale). In 2D the rotation has a closed form: atan2(sum a x b, sum a . b) over the
    centred points."""
    source_mean, target_mean = source.mean(axis=0), target.mean(axis=0)
    a, b = source - source_mean, target - target_mean
    rotation_rad = math.atan2(
        float(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])), float(np.sum(a * b))
    )
    turned_mean = transform_points(np.array([0.0, 0.0, rotation_rad]), source_mean[None])[0]
    return np.array([*(target_mean - turned_mean), rotation_rad])


def path_length_m(points_m: np.ndarray) -> float:
    """Length in metres of a polyline of (N, 2) points."""
    return float(np.linalg.norm(np.diff(np.asarray(points_m, dtype=float), axis=0), axis=1).sum())
