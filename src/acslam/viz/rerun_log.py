"""``--viz rerun``: what the server knows, logged to a Rerun recording or live viewer.

Entities (2D, world frame, metres; timeline ``sim`` in seconds of run time):

- ``world/map``: the team's occupancy grid (OccupancyGrid values, RViz colours), cropped
  to the known window; ``world/costmap``: the planners' costmap (lethal = 100);
- ``world/frontiers``: frontier cells; ``world/allocations``: an arrow from each robot to
  its assigned frontier target;
- ``world/robots/robot_<i>/{pose,trajectory,scan,path}``: estimated pose, estimated
  trajectory, the last LiDAR scan's returns at the estimated pose, the global A* path.

Grids, frontiers and trajectories are logged every ``map_period_s`` and scans every
``scan_period_s`` of run time, poses and paths every step: a full thesis-exp1 run stays
a few tens of MB. rerun-sdk is the optional extra ``viz``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from acslam.errors import VizError
from acslam.geometry import beam_ends
from acslam.grid import GridSpec
from acslam.messages import LidarScan, RobotMessage
from acslam.pipeline.snapshot import Snapshot
from acslam.scenario import Scenario

try:
    import rerun as rr
except ImportError:  # pragma: no cover - depends on the installed extras
    rr = None


class RerunLogger:
    """Logs one run; ``out`` is an .rrd file, or ``None`` for a spawned live viewer."""

    def __init__(
        self,
        scenario: Scenario,
        out: Path | None,
        map_period_s: float = 1.0,
        scan_period_s: float = 0.5,
    ) -> None:
        if rr is None:
            raise VizError("--viz rerun: rerun-sdk is not installed: pip install acslam[viz]")
        self.robot_count = scenario.robot_count
        self.spec = scenario.world.spec
        self.map_period_s = map_period_s
        self.scan_period_s = scan_period_s
        self._next_map_s = 0.0
        self._next_scan_s = 0.0
        self._last_scans: dict[int, LidarScan] = {}
        self.recording = rr.RecordingStream("acslam", recording_id=None)
        if out is not None:
            Path(out).parent.mkdir(parents=True, exist_ok=True)
            self.recording.save(str(out))
        else:
            try:
                self.recording.spawn()
            except Exception as exc:  # no viewer binary or no display
                raise VizError(
                    f"--viz rerun: cannot spawn a Rerun viewer ({exc}); give --viz-out FILE.rrd"
                ) from None
        self.recording.send_property("scenario", rr.AnyValues(name=scenario.config.name))

    def log_step(self, snapshot: Snapshot, messages: list[RobotMessage]) -> None:
        """Log the server's snapshot after a step on ``messages``."""
        rec = self.recording
        now_s = snapshot.time_s
        rec.set_time("sim", duration=now_s)
        for message in messages:
            if isinstance(message, LidarScan):
                self._last_scans[message.robot_id] = message
        poses = snapshot.poses
        for i, path_m in enumerate(snapshot.paths_m):
            base = f"world/robots/robot_{i}"
            rec.log(f"{base}/pose", rr.Points2D(poses[i : i + 1, :2], radii=0.1))
            if path_m is not None:
                rec.log(f"{base}/path", rr.LineStrips2D([path_m]))
            else:
                rec.log(f"{base}/path", rr.Clear(recursive=False))
        if now_s >= self._next_scan_s:
            self._next_scan_s = now_s + self.scan_period_s
            for i, scan in self._last_scans.items():
                rec.log(f"world/robots/robot_{i}/scan", rr.Points2D(_returns(scan, poses[i])))
        if now_s >= self._next_map_s:
            self._next_map_s = now_s + self.map_period_s
            self._log_maps(snapshot)

    def _log_maps(self, snapshot: Snapshot) -> None:
        rec = self.recording
        poses = snapshot.poses
        values = snapshot.map.occupancy_values()
        costmap, window = snapshot.costmap, snapshot.window
        if costmap is not None and window is not None:
            rec.log("world/map", _grid(window.crop(values).view(np.uint8), window.spec, "RvizMap"))
            cost = np.where(costmap.lethal, 100.0, np.minimum(costmap.cost, 1.0) * 99.0)
            rec.log("world/costmap", _grid(cost.astype(np.uint8), window.spec, "RvizCostmap"))
        cells = snapshot.frontier_cells
        if len(cells):
            rec.log("world/frontiers", rr.Points2D(self.spec.cell_to_world(cells), radii=0.03))
        goals = [(i, goal) for i, goal in enumerate(snapshot.goals_m) if goal is not None]
        rec.log(
            "world/allocations",
            rr.Arrows2D(
                origins=[poses[i, :2] for i, _ in goals] or np.zeros((0, 2)),
                vectors=[target - poses[i, :2] for i, target in goals] or np.zeros((0, 2)),
                labels=[f"robot_{i}" for i, _ in goals],
            ),
        )
        for i in range(self.robot_count):
            _, trajectory = snapshot.localization.trajectory(i)
            rec.log(f"world/robots/robot_{i}/trajectory", rr.LineStrips2D([trajectory[:, :2]]))

    def close(self) -> None:
        self.recording.flush()
        self.recording.disconnect()


def _returns(scan: LidarScan, pose: np.ndarray) -> np.ndarray:
    """World coordinates of the scan's returns (finite, valid ranges) seen from ``pose``."""
    hit = np.isfinite(scan.ranges) & (scan.ranges > 0)
    return beam_ends(pose, scan.angles[hit], scan.ranges[hit])


def _grid(cells: np.ndarray, spec: GridSpec, colormap: str) -> rr.GridMap:
    """A GridMap of uint8 cells (row 0 at the bottom, like the grid's y axis)."""
    return rr.GridMap(
        data=np.ascontiguousarray(cells).tobytes(),
        format=rr.components.ImageFormat(
            width=spec.cols, height=spec.rows, color_model="L", channel_datatype="U8"
        ),
        cell_size=spec.resolution_m,
        translation=[spec.origin_x_m, spec.origin_y_m, 0.0],
        colormap=getattr(rr.components.Colormap, colormap),
    )
