"""The patrol after exploring: waypoints that cover the free space, a tour, a run that
keeps driving over a finished map and reports each stage's cost at its start and end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from acslam.cli import print_run_summary
from acslam.exploration.patrol import Patrol, patrol_waypoints
from acslam.grid import GridSpec
from acslam.runner import run_exploration
from acslam.scenario import load_scenario

SPEC = GridSpec(0.0, 0.0, 0.1, 40, 80)


def l_shaped_free_space() -> np.ndarray:
    """An L of free cells: a 4 m x 1 m corridor and a 1 m x 3 m leg."""
    free = np.zeros(SPEC.shape, dtype=bool)
    free[0:10, 0:40] = True
    free[10:40, 30:40] = True
    return free


def test_waypoints_cover_the_free_space_within_the_spacing() -> None:
    free = l_shaped_free_space()
    waypoints = patrol_waypoints(free, SPEC, 1.0, np.array([0.0, 0.0]))
    centres = SPEC.cell_to_world(np.argwhere(free))
    # Brute force: every free cell is within the spacing of some waypoint ...
    assert cdist(centres, waypoints).min(axis=1).max() <= 1.0
    # ... every waypoint is on a free cell, the first the one nearest the start ...
    assert free[tuple(SPEC.world_to_cell(waypoints).T)].all()
    np.testing.assert_allclose(waypoints[0], [0.05, 0.05])
    # ... and farthest-point sampling keeps them apart by more than the spacing.
    gaps = cdist(waypoints, waypoints) + np.eye(len(waypoints)) * 1e9
    assert gaps.min() > 1.0
    again = patrol_waypoints(free, SPEC, 1.0, np.array([0.0, 0.0]))
    np.testing.assert_array_equal(waypoints, again)


def test_the_tour_steps_to_the_nearest_waypoint_left() -> None:
    waypoints = patrol_waypoints(l_shaped_free_space(), SPEC, 1.0, np.array([0.0, 0.0]))
    for k in range(len(waypoints) - 1):
        left = waypoints[k + 1 :]
        step = np.linalg.norm(waypoints[k + 1] - waypoints[k])
        assert step == pytest.approx(np.linalg.norm(left - waypoints[k], axis=1).min())


def test_robots_start_spread_over_the_tour_and_skip_what_they_cannot_reach() -> None:
    waypoints = np.arange(6.0).repeat(2).reshape(6, 2)  # waypoint k at (k, k)
    patrol = Patrol(waypoints, 3, started_s=10.0)
    assert [patrol.goal_m(i)[0] for i in range(3)] == [0.0, 2.0, 4.0]
    # Robot 2 reached waypoint 4: next is 5. It cannot reach 5, so it gets 0 (the tour wraps).
    goals = patrol.goals(2, reached=True)
    assert next(goals).target_m[0] == 5.0
    assert next(goals).target_m[0] == 0.0
    assert patrol.goal_m(2)[0] == 0.0
    # Nothing reachable: once round, then no more goals.
    assert len(list(patrol.goals(0, reached=False))) == 6


def test_a_run_patrols_after_exploring_and_reports_start_and_end(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    patrol_s = 20.0
    scenario = load_scenario("thesis-exp1", robots=3).with_patrol(patrol_s)
    metrics = run_exploration(scenario, tmp_path, max_time_s=400.0)
    assert metrics["completed"], metrics["reason"]
    patrol = metrics["patrol"]
    # Exploring ended when every robot had been idle for finish_after_idle_s (4 s).
    assert patrol["start_s"] == pytest.approx(metrics["timing"]["total_s"] + 4.0)
    replan_s = scenario.config.algorithms.planning.replan_period_s
    assert patrol_s <= metrics["sim_time_s"] - patrol["start_s"] <= patrol_s + replan_s + 0.1
    assert set(patrol["stages"]) >= {"cycle", "slam", "mapping", "local_planning"}
    for stage in patrol["stages"].values():
        assert stage["growth"] == pytest.approx(
            stage["last_tenth_p95_ms"] / stage["first_tenth_p95_ms"]
        )
    for i in range(3):  # every robot drove on after exploring
        truth = np.loadtxt(tmp_path / "trajectories" / f"robot_{i}.groundtruth.tum")
        after = truth[truth[:, 0] >= patrol["start_s"], 1:3]
        assert np.linalg.norm(np.diff(after, axis=0), axis=1).sum() > 1.0
    assert metrics["safety"]["obstacle_collisions"] == 0
    assert "patrol" in json.loads((tmp_path / "metrics.json").read_text())
    assert "Server cycle over the patrol" in (tmp_path / "report.html").read_text()
    print_run_summary(metrics)
    cycle = patrol["stages"]["cycle"]
    assert (
        f"patrol from {patrol['start_s']:.0f} s to {metrics['sim_time_s']:.0f} s: server cycle "
        f"p95 {cycle['first_tenth_p95_ms']:.1f} ms over its first tenth"
    ) in capsys.readouterr().out
