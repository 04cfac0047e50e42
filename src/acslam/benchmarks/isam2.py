"""iSAM2 update time per keyframe against graph size, on a synthetic multi-robot run.

The robots drive overlapping circles through a grid of landmarks, so every lap closes
loops with their own and the other robots' landmarks: the case where iSAM2 re-factors
the most. Each robot's odometry increment is one keyframe; one back-end update follows
each server cycle, in which every robot adds a keyframe with its landmark points (the
server batches a cycle's messages into one update). The time measured is
:meth:`SlamBackend.update` alone (iSAM2 update + estimate refresh), and apart from it each
frame's landmark association (:meth:`SlamBackend.add_landmarks`). "Per keyframe" divides
an update by the keyframes it added. Ground truth, odometry noise and camera noise come
from one seeded generator, so a seed gives the same run.
"""

from __future__ import annotations

import math
import time

import numpy as np

from acslam.benchmarks.core import spread_ms
from acslam.config import SlamConfig
from acslam.geometry import between
from acslam.messages import LandmarkObservations, OdometryIncrement
from acslam.slam.backend import SlamBackend

STEP_M = 0.3  # path per keyframe (= the default keyframe distance)
RADIUS_M = 4.0
LANDMARK_SPACING_M = 1.5
CAMERA_RANGE_M = 4.0
CAMERA_HALF_FOV_RAD = 0.6
POINT_SIGMA_M = 0.03
ODOM_SIGMA = np.array([0.01, 0.005, 0.005])  # per step: x, y (m), theta (rad)
BUCKET = 500


def _landmark_grid(centers: np.ndarray) -> np.ndarray:
    low = centers.min(axis=0) - RADIUS_M - CAMERA_RANGE_M
    high = centers.max(axis=0) + RADIUS_M + CAMERA_RANGE_M
    xs = np.arange(low[0], high[0], LANDMARK_SPACING_M)
    ys = np.arange(low[1], high[1], LANDMARK_SPACING_M)
    grid = np.array([(x, y) for x in xs for y in ys])
    return np.column_stack([grid, np.zeros(len(grid))])


def _circle_pose(center: np.ndarray, angle: float) -> np.ndarray:
    """Pose on a counter-clockwise circle, heading along the tangent."""
    x = center[0] + RADIUS_M * math.cos(angle)
    y = center[1] + RADIUS_M * math.sin(angle)
    return np.array([x, y, angle + math.pi / 2])


def _visible(pose: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rel = landmarks[:, :2] - pose[:2]
    local = np.column_stack([c * rel[:, 0] + s * rel[:, 1], -s * rel[:, 0] + c * rel[:, 1]])
    distance = np.hypot(local[:, 0], local[:, 1])
    bearing = np.arctan2(local[:, 1], local[:, 0])
    keep = (distance <= CAMERA_RANGE_M) & (np.abs(bearing) <= CAMERA_HALF_FOV_RAD)
    return np.column_stack([local[keep], np.zeros(int(keep.sum()))])


def measure_isam2_updates(keyframes: int, robots: int, seed: int) -> dict:
    """Run ``keyframes`` keyframes (all robots together) and time every update and every
    frame's landmark association.

    Returns ``{"keyframes", "robots", "seed", "buckets": [{"from", "to", "updates",
    "mean_ms", "p95_ms", "max_ms", "per_keyframe_p95_ms", "association_mean_ms",
    "association_p95_ms"}], "mean_ms", "p95_ms", "per_keyframe_mean_ms",
    "per_keyframe_p95_ms", "landmarks", "final_position_error_m"}``: update times per
    bucket of 500 keyframes of graph size (per keyframe: an update divided by the
    keyframes it added), association time per frame; the worst robot's final position
    error shows that the speed settings did not cost accuracy.
    """
    if keyframes < 1 or robots < 1:
        raise ValueError("keyframes and robots must be >= 1")
    rng = np.random.default_rng(seed)
    centers = np.array(
        [
            [2.5 * math.cos(2 * math.pi * r / robots), 2.5 * math.sin(2 * math.pi * r / robots)]
            for r in range(robots)
        ]
    )
    landmarks = _landmark_grid(centers)
    # Every step opens a keyframe, on each lap too: the graph holds ``keyframes`` poses.
    config = SlamConfig(
        landmark_sigma_m=POINT_SIGMA_M,
        keyframe_distance_m=0.5 * STEP_M,
        mapped_keyframe_distance_m=0.0,
    )
    angles = rng.uniform(0.0, 2 * math.pi, robots)
    truth = [_circle_pose(centers[r], angles[r]) for r in range(robots)]
    backend = SlamBackend(config, {r: truth[r].copy() for r in range(robots)})
    step_angle = STEP_M / RADIUS_M
    durations: list[float] = []
    sizes: list[int] = []
    added: list[int] = []
    association_s: list[float] = []
    association_sizes: list[int] = []
    done = 0
    while done < keyframes:
        stamp = 1.0 + done // robots
        cycle = min(robots, keyframes - done)
        for r in range(cycle):
            angles[r] += step_angle
            new_truth = _circle_pose(centers[r], angles[r])
            delta = between(truth[r], new_truth) + rng.normal(scale=ODOM_SIGMA)
            truth[r] = new_truth
            backend.add_odometry(OdometryIncrement(r, stamp, stamp - 1.0, *delta))
            points = _visible(new_truth, landmarks)
            points = points + rng.normal(scale=POINT_SIGMA_M, size=points.shape)
            if len(points):
                started = time.perf_counter()
                backend.add_landmarks(LandmarkObservations(r, stamp, points))
                association_s.append(time.perf_counter() - started)
                association_sizes.append(done + 1)
            done += 1
        before = len(backend.update_durations_s)
        backend.update()
        durations.extend(backend.update_durations_s[before:])
        sizes.extend([done] * (len(backend.update_durations_s) - before))
        added.extend([cycle] * (len(backend.update_durations_s) - before))
    update_ms = np.array(durations) * 1e3
    per_keyframe_ms = update_ms / np.array(added)
    association_ms = np.array(association_s) * 1e3
    sizes_array, association_at = np.array(sizes), np.array(association_sizes)
    buckets = []
    for start in range(0, keyframes, BUCKET):
        here = (sizes_array > start) & (sizes_array <= start + BUCKET)
        if not here.any():
            continue
        chunk = update_ms[here]
        frames = association_ms[(association_at > start) & (association_at <= start + BUCKET)]
        buckets.append(
            {
                "from": start,
                "to": min(start + BUCKET, keyframes),
                "updates": len(chunk),
                **spread_ms(chunk),
                "max_ms": float(chunk.max()),
                "per_keyframe_p95_ms": float(np.percentile(per_keyframe_ms[here], 95)),
                **spread_ms(frames, "association_", empty=0.0),
            }
        )
    return {
        "keyframes": keyframes,
        "robots": robots,
        "seed": seed,
        "buckets": buckets,
        "mean_ms": float(update_ms.mean()),
        "p95_ms": float(np.percentile(update_ms, 95)),
        "per_keyframe_mean_ms": float(per_keyframe_ms.mean()),
        "per_keyframe_p95_ms": float(np.percentile(per_keyframe_ms, 95)),
        "landmarks": len(backend.landmarks()),
        "final_position_error_m": max(
            float(np.linalg.norm(backend.latest_pose(r)[:2] - truth[r][:2])) for r in range(robots)
        ),
    }
