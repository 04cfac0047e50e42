"""Odometry-only map of the Intel Lab log: an end-to-end check of reader + TeamMap.

Without SLAM the raw odometry drifts, so the walls smear; the map should still show the
lab's corridor structure near the start. Writes a PNG and prints the timing.

Run: ``python benchmarks/intel_odometry_map.py [out.png [log]]``; with the GMapping-corrected
log (``intel-corrected.log.gz``) as ``log`` the same pipeline gives a sharp map.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from acslam.config import MappingConfig
from acslam.datasets.carmen import read_carmen
from acslam.eval.plotting import plt, save_figure
from acslam.mapping.occupancy import TeamMap, grid_spec_for_bounds

LOG = Path(__file__).resolve().parents[2] / "shared/datasets/intel_lab_carmen/intel.clf.bz2"
MAX_RANGE_M = 15.0


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("intel_odometry_map.png")
    log_path = Path(sys.argv[2]) if len(sys.argv) > 2 else LOG
    log = read_carmen(log_path)
    poses = np.array([scan.laser_pose_xytheta for scan in log.scans])
    low = poses[:, :2].min(axis=0) - MAX_RANGE_M
    high = poses[:, :2].max(axis=0) + MAX_RANGE_M
    config = MappingConfig(max_range_m=MAX_RANGE_M)
    spec = grid_spec_for_bounds(low[0], low[1], high[0], high[1], config.resolution_m)
    team = TeamMap(config, spec=spec)
    start = time.perf_counter()
    for index, scan in enumerate(log.scans):
        team.add_scan(0, index, scan.ranges_m, scan.angles_rad, scan.laser_pose_xytheta)
    elapsed_s = time.perf_counter() - start
    print(
        f"{len(log.scans)} scans on {spec.rows} x {spec.cols} cells in {elapsed_s:.1f} s "
        f"({1e3 * elapsed_s / len(log.scans):.2f} ms per scan, global + robot grid)"
    )

    values = team.global_grid.to_occupancy_values()
    image = np.select([values == 100, values == 0], [0.0, 1.0], default=0.6)
    extent = (
        spec.origin_x_m,
        spec.origin_x_m + spec.width_m,
        spec.origin_y_m,
        spec.origin_y_m + spec.height_m,
    )
    fig, ax = plt.subplots(figsize=(8, 8))
    ax.imshow(image, cmap="gray", origin="lower", extent=extent, vmin=0.0, vmax=1.0)
    ax.plot(poses[:, 0], poses[:, 1], lw=0.3, color="tab:red")
    ax.set(title=f"{log_path.name}: scans at the logged poses", xlabel="x [m]", ylabel="y [m]")
    save_figure(fig, out, dpi=150)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
