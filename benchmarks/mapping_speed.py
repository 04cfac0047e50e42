"""Mapping speed: scan integration and costmap update on an 800 x 800 grid at 0.05 m.

Goals (thesis-scale maps, 10 Hz LiDAR): <= 2 ms per 360-beam 8 m scan, <= 20 ms per
costmap. Each time is also printed as a ratio to ``np.copy`` of an 800 x 800 float64
array measured in the same process, so figures compare across machines.

Run: ``python benchmarks/mapping_speed.py``
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from timing import median_ms

from acslam.config import CostmapConfig, MappingConfig
from acslam.mapping import LogOddsGrid, TeamMap, compute_costmap, grid_spec_for_bounds


def room_ranges(pose: np.ndarray, angles: np.ndarray, half_size_m: float) -> np.ndarray:
    """Ranges to the walls of a square room centred at the origin, inf beyond 8 m."""
    dx, dy = np.cos(pose[2] + angles), np.sin(pose[2] + angles)
    with np.errstate(divide="ignore"):
        tx = (np.sign(dx) * half_size_m - pose[0]) / dx
        ty = (np.sign(dy) * half_size_m - pose[1]) / dy
    ranges = np.minimum(np.abs(tx), np.abs(ty))
    ranges[ranges > 8.0] = np.inf
    return ranges


def main() -> None:
    spec = grid_spec_for_bounds(-20.0, -20.0, 20.0, 20.0, 0.05)
    grid = LogOddsGrid(spec, MappingConfig(max_range_m=8.0))
    reference = np.zeros(spec.shape)
    copy_ms = median_ms(lambda: np.copy(reference), 200)

    rng = np.random.default_rng(0)
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    poses = [np.array([*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi)]) for _ in range(50)]
    scans = [(room_ranges(pose, angles, 7.0), pose) for pose in poses]
    for ranges, pose in scans:
        grid.integrate(ranges, angles, pose)
    index = iter(range(10**9))

    def integrate_one() -> None:
        ranges, pose = scans[next(index) % len(scans)]
        grid.integrate(ranges, angles, pose)

    scan_ms = median_ms(integrate_one, 300)
    team = TeamMap(spec, grid.config)
    team.add_scan(0, "moved", scans[0][0], angles, scans[0][1])
    shifts = iter(range(10**9))

    def move_one() -> None:
        offset = 0.02 if next(shifts) % 2 else 0.0
        team.move_scan("moved", scans[0][1] + offset)

    move_ms = median_ms(move_one, 100)

    values = grid.to_occupancy_values()
    costmap_cfg = CostmapConfig()
    costmap_ms = median_ms(lambda: compute_costmap(values, spec, costmap_cfg, 0.105), 30)
    occupied = values == 100
    edt_ms = median_ms(lambda: ndimage.distance_transform_edt(~occupied), 30)
    classify_ms = median_ms(grid.to_occupancy_values, 30)

    print(
        f"grid {spec.rows} x {spec.cols} at {spec.resolution_m} m; reference np.copy of the "
        f"float64 grid: {copy_ms:.3f} ms"
    )
    rows = [
        ("scan integration (360 beams, 8 m)", scan_ms, 2.0),
        ("TeamMap.move_scan (global + robot)", move_ms, None),
        ("occupancy values (-1/0/100)", classify_ms, None),
        ("costmap (EDT + decay + lethal)", costmap_ms, 20.0),
        ("  of which scipy EDT alone", edt_ms, None),
    ]
    for name, ms, goal in rows:
        verdict = (
            "" if goal is None else f"  goal <= {goal:g} ms: {'met' if ms <= goal else 'MISSED'}"
        )
        print(f"{name:36s} {ms:8.3f} ms  = {ms / copy_ms:7.1f} x np.copy{verdict}")


if __name__ == "__main__":
    main()
