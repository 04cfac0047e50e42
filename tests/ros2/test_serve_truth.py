"""A ROS 2 served run of real robots, which publish no ground truth, still writes its
run folder: scored on what needs no truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acslam import runner
from acslam.pipeline.frames import FramedServer
from acslam.pipeline.server import Server
from acslam.ros2.serve import topic_truth
from acslam.scenario import load_scenario


class _RealTeam:
    """What :func:`topic_truth` reads of a source whose robots publish no ground truth."""

    def truth(self) -> list[np.ndarray]:
        return [np.zeros((0, 4)), np.zeros((0, 4))]


@pytest.mark.parametrize("relative_starts", ["known", "unknown"])
def test_a_team_without_ground_truth_gets_its_metrics_written(
    relative_starts: str, tmp_path: Path
) -> None:
    scenario = load_scenario("thesis-exp1", robots=2)
    server: Server | FramedServer
    if relative_starts == "unknown":
        scenario = scenario.with_unknown_starts()
        server = FramedServer(scenario.config, 2, scenario.world.spec)
    else:
        server = Server(scenario.config, scenario.starts, scenario.world.spec)
    log = runner.RunLog(scenario.world.spec, server.snapshot(0.0), true_starts=scenario.starts)
    out = runner.start_run_folder(tmp_path / "run", scenario)
    truth = topic_truth(_RealTeam())  # type: ignore[arg-type]
    metrics = runner.finish_run(out, scenario, log, truth, reason="time limit",
                                wall_time_s=1.0, time_s=1.0)  # fmt: skip
    assert metrics["localization"] == {} and metrics["team_alignment"] is None
    assert metrics["safety"]["robot_collisions"] is None
    assert metrics["safety"]["min_robot_distance_m"] is None
    assert (out / "metrics.json").is_file() and (out / "report.html").is_file()
