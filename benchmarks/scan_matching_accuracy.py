"""Sequential scan matches against the truth: error, calibration and heading drift.

Replays the true paths of finished runs (``acslam run ... --out RUN``): keyframes where
the SLAM stage would make them (``keyframe_distance_m`` / ``keyframe_angle_rad`` along
the way), a fresh scan of the run's LiDAR at each (seeded; no teammates in view), and
each keyframe matched to a submap of the previous ``n`` keyframes' scans placed at their
true poses (so this is the best case of the ``scan_matching.submap_keyframes`` setting),
from a guess 2 cm / 5 mrad off the truth (seeded). With ``--keyframe-scans n`` each
keyframe contributes its first ``n`` scans at the LiDAR's rate while it lasts, on both
sides: the reference merges them, the query stacks them. They are placed at their true
poses turned by a gyro bias (drawn per robot from the run's
``sensors.odometry.bias_omega_std_radps``) times their time since the keyframe's first
scan, as odometry would place them. Per setting: heading error std,
position error RMS, the squared Mahalanobis error of the match's covariance (median, and
the share beyond chi-square 3-dof 99.9 %, 16.27; a covariance that holds the errors
gives a median of 2.37), the heading error summed over 20 consecutive matches (the drift
a chain of them leaves), and time per match. Rejected matches are counted, not scored.

Run: ``acslam run --scenario examples/floorplan-office-a.yaml --max-time 200 --out RUN``,
then ``python benchmarks/scan_matching_accuracy.py RUN [RUN ...] [--submaps 1 2 5]
[--keyframe-scans 1 3 9]``.
``--algorithms carmen`` (a preset or an algorithms YAML, as a replay takes) scores that
one's scan matching and keyframe spacing instead of the run's own, e.g. on the SICK-like
run of ``examples/sick-laser-lab-ipa.yaml``.
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig, ScanMatchingConfig
from acslam.geometry import between, compose, wrap_angle
from acslam.mapping.scan_matching import (
    match_scans,
    merged_reference,
    scan_points,
    stacked_scans,
    verify,
)
from acslam.replay import algorithms_config
from acslam.scenario import load_scenario
from acslam.sim.lidar import LidarSensor
from acslam.trajectory import read_tum

GUESS_SIGMAS = np.array([0.02, 0.02, 0.005])  # m, m, rad: about one keyframe of odometry
CHAIN_MATCHES = 20
CHI2_3DOF_999 = 16.27


def keyframe_rows(poses: np.ndarray, distance_m: float, angle_rad: float) -> list[int]:
    """Rows of a true path where a keyframe starts: the first, then each pose at least
    ``distance_m`` or ``angle_rad`` from the previous keyframe."""
    rows = [0]
    for row in range(1, len(poses)):
        step = between(poses[rows[-1]], poses[row])
        if np.hypot(step[0], step[1]) >= distance_m or abs(step[2]) >= angle_rad:
            rows.append(row)
    return rows


def keyframe_scans(
    run: Path, seed: int, algorithms: AlgorithmsConfig | None, scans_per_keyframe: int
) -> tuple[list[list], ScanMatchingConfig]:
    """Per robot of a run, per keyframe, its first ``scans_per_keyframe`` scans (at the
    LiDAR's rate, until the next keyframe starts) as ``(true pose, odometry's pose relative
    to the keyframe's first scan, scan points)``; and the scan matching config
    (``algorithms``' if given, else the run's)."""
    scenario = load_scenario(run / "config.yaml")
    config = scenario.config
    algorithms = config.algorithms if algorithms is None else algorithms
    localizer = algorithms.localizer
    matching = algorithms.scan_matching
    # Three generators, so a keyframe's first scans are the same however many later ones
    # are drawn (and the same as with one scan per keyframe).
    first_sensor = LidarSensor(config.sensors.lidar, scenario.world, np.random.default_rng(seed))
    later_sensor = LidarSensor(
        config.sensors.lidar, scenario.world, np.random.default_rng([seed, 1])
    )
    gyro_rng = np.random.default_rng([seed, 2])
    scan_period_s = 1.0 / config.sensors.lidar.rate_hz
    robots = []
    for robot_id in range(scenario.robot_count):
        stamps, poses = read_tum(run / "trajectories" / f"robot_{robot_id}.groundtruth.tum")
        gyro_bias_radps = gyro_rng.normal(0.0, config.sensors.odometry.bias_omega_std_radps)
        starts = keyframe_rows(poses, localizer.keyframe_distance_m, localizer.keyframe_angle_rad)
        keyframes = []
        for first, end in zip(starts, [*starts[1:], len(poses)], strict=True):
            rows = [first]
            for row in range(first + 1, end):
                if (
                    len(rows) < scans_per_keyframe
                    and stamps[row] >= stamps[rows[-1]] + scan_period_s - 1e-9
                ):
                    rows.append(row)
            scans = []
            for row in rows:
                sensor = first_sensor if row == first else later_sensor
                scan = sensor.scan(
                    robot_id, float(stamps[row]), tuple(poses[row]), np.zeros((0, 3)), -1
                )
                placed = between(poses[first], poses[row])
                placed[2] += gyro_bias_radps * float(stamps[row] - stamps[first])
                scans.append((poses[row], placed, scan_points(scan.angles, scan.ranges, matching)))
            keyframes.append(scans)
        robots.append(keyframes)
    return robots, matching


def score(
    robots: list[list], config: ScanMatchingConfig, submap: int, scans_per_keyframe: int, seed: int
) -> dict:
    rng = np.random.default_rng(seed)
    errors, squared, chains, rejected, seconds = [], [], [], 0, 0.0
    for keyframes in robots:
        headings = []
        for index in range(submap, len(keyframes)):
            pose_a = keyframes[index - 1][0][0]
            pose_b = keyframes[index][0][0]
            query = stacked_scans(
                [(placed, points) for _, placed, points in keyframes[index][:scans_per_keyframe]]
            )
            truth = between(pose_a, pose_b)
            guess = truth + rng.normal(0.0, GUESS_SIGMAS)
            start = time.perf_counter()
            # Newest first, as SLAM merges them: the voxel filter keeps a cell's first return.
            reference = merged_reference(
                [
                    (compose(between(pose_a, scans[0][0]), placed), points)
                    for scans in reversed(keyframes[index - submap : index])
                    for _, placed, points in reversed(scans[:scans_per_keyframe])
                ],
                config,
            )
            result = match_scans(reference, query, guess, config, guess_from_odometry=True)
            seconds += time.perf_counter() - start
            if not verify(result, guess, config, strict=False):
                rejected += 1
                continue
            error = result.relative - truth
            error[2] = wrap_angle(float(error[2]))
            errors.append(error)
            squared.append(float(error @ np.linalg.solve(result.covariance, error)))
            headings.append(error[2])
        chains += [
            sum(headings[i : i + CHAIN_MATCHES])
            for i in range(0, len(headings) - CHAIN_MATCHES, CHAIN_MATCHES)
        ]
    errors_array, squared_array = np.array(errors), np.array(squared)
    return {
        "matches": len(errors),
        "rejected": rejected,
        "heading_std_mrad": 1e3 * float(errors_array[:, 2].std()),
        "position_rms_mm": 1e3 * float(np.sqrt(np.mean(np.sum(errors_array[:, :2] ** 2, axis=1)))),
        "mahalanobis2_median": float(np.median(squared_array)),
        "beyond_999_pct": 100.0 * float(np.mean(squared_array > CHI2_3DOF_999)),
        "chain_heading_rms_mrad": 1e3 * float(np.sqrt(np.mean(np.square(chains)))),
        "chains": len(chains),
        "ms_per_match": 1e3 * seconds / max(len(errors) + rejected, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+", help="folders of finished acslam runs")
    parser.add_argument("--submaps", type=int, nargs="+", default=[1, 2, 5])
    parser.add_argument(
        "--keyframe-scans", type=int, nargs="+", default=[1], help="scans per keyframe"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--algorithms", help="a preset's name or an algorithms YAML")
    args = parser.parse_args()
    algorithms = None if args.algorithms is None else algorithms_config(args.algorithms)
    robots, config = [], None
    for run in args.runs:
        run_robots, config = keyframe_scans(run, args.seed, algorithms, max(args.keyframe_scans))
        robots += run_robots
    print(
        f"{sum(len(k) for k in robots)} keyframes of {len(robots)} robots in {len(args.runs)} runs"
    )
    print(
        "submap keyframes | scans per keyframe | matches (rejected) | heading std | position RMS | "
        "Mahalanobis^2 median | beyond 99.9 % | heading over 20 matches | time per match"
    )
    for submap, scans in itertools.product(args.submaps, args.keyframe_scans):
        s = score(robots, config, submap, scans, args.seed)
        print(
            f"{submap} | {scans} | {s['matches']} ({s['rejected']}) | "
            f"{s['heading_std_mrad']:.2f} mrad | "
            f"{s['position_rms_mm']:.1f} mm | {s['mahalanobis2_median']:.2f} | "
            f"{s['beyond_999_pct']:.1f} % | {s['chain_heading_rms_mrad']:.1f} mrad "
            f"({s['chains']} chains) | {s['ms_per_match']:.1f} ms"
        )


if __name__ == "__main__":
    main()
