"""The Ray executor gives the same run folders and metrics as the process pool."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from acslam.experiments.grid import expand, parse_grid
from acslam.experiments.sweep import ProcessPoolRunner, sweep

ray = pytest.importorskip("ray", reason="Ray is an optional extra: pip install 'acslam[ray]'")

# Wall-clock figures differ from run to run whatever runs them, and provenance records
# when and in which process a run was made; everything else must not differ.
UNREPEATABLE_KEYS = {"wall_time_s", "real_time_factor", "server_cycle_ms", "provenance"}


def _metrics(folder: Path) -> dict:
    metrics = json.loads((folder / "metrics.json").read_text())
    return {k: v for k, v in metrics.items() if k not in UNREPEATABLE_KEYS}


def test_ray_and_process_pool_give_the_same_runs(tmp_path: Path) -> None:
    from acslam.experiments.ray_executor import RayRunner

    grid = parse_grid(
        {
            "name": "tiny",
            "max_time_s": 6,
            "blocks": [{"scenarios": ["thesis-exp1"], "robots": [1, 2]}],
        },
        "tiny.yaml",
    )
    specs = expand(grid)
    by_pool = sweep(specs, tmp_path / "pool", ProcessPoolRunner(2))
    by_ray = sweep(specs, tmp_path / "ray", RayRunner())
    assert sorted(r.run_id for r in by_ray) == sorted(r.run_id for r in by_pool)
    for spec in specs:
        pool_folder = tmp_path / "pool" / "runs" / spec.run_id
        ray_folder = tmp_path / "ray" / "runs" / spec.run_id
        assert _metrics(ray_folder) == _metrics(pool_folder)
        assert (ray_folder / "report.html").is_file()
        assert (ray_folder / "trajectories").is_dir()


@pytest.mark.slow
def test_a_signal_to_the_driver_stops_ray_runs_with_their_results(tmp_path: Path) -> None:
    """SIGTERM to a Ray sweep's driver: the running run ends at its next step with its
    metrics and report (reason ``interrupted``: ``ray.cancel`` interrupts with SIGINT), and
    the run still waiting for a CPU never starts, so a resume runs it."""
    import os
    import signal
    import threading

    from acslam import stop
    from acslam.experiments.ray_executor import RayRunner

    # A run that outlasts the signal on any machine: one robot on an 80 m dungeon explores
    # for over an hour of simulated time, minutes of wall time even at 30x real time.
    world = tmp_path / "big-dungeon.yaml"
    world.write_text(
        "name: big-dungeon\n"
        "world: {generator: dungeon, width_m: 80.0, height_m: 80.0, room_count: 40}\n"
        "robots: {count: 1}\n"
    )
    grid = parse_grid(
        {
            "name": "long",
            "max_time_s": 3600,
            "blocks": [{"scenarios": [str(world)], "robots": [1], "seeds": [0, 1]}],
        },
        "long.yaml",
    )
    specs = expand(grid)
    timer = threading.Timer(15.0, os.kill, (os.getpid(), signal.SIGTERM))
    with stop.on_signals() as signals:
        timer.start()
        results = sweep(specs, tmp_path, RayRunner(local_cpus=1))
    assert signals.reason == "terminated"
    (result,) = results
    assert result.reason == "interrupted" and result.status == "incomplete"
    folder = tmp_path / "runs" / result.run_id
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["reason"] == "interrupted" and metrics["sim_time_s"] < 3600
    assert (folder / "report.html").is_file()
    (never_started,) = [s for s in specs if s.run_id != result.run_id]
    assert not (tmp_path / "runs" / never_started.run_id / "metrics.json").exists()
