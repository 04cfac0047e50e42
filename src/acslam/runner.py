"""Closes the loop of thesis Fig. 4.2 on the simulated clock and writes the run folder.

Every control period the server gets the messages the robots sent since the last one
and answers with velocity commands; the simulator advances until the next period.
Ground truth is read only after the run, for the metrics. Whatever happens, the run folder
gets ``config.yaml`` first and ``metrics.json`` last, with ``completed`` and ``reason``,
so a failed or timed-out run keeps what it produced.
"""

from __future__ import annotations

import json
import math
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np
import yaml

from acslam.errors import AcslamError
from acslam.eval.metrics import (
    confusion_rates,
    coverage_by_combination,
    localization_errors,
    timing,
)
from acslam.eval.report import RunRecord, write_report
from acslam.messages import RobotMessage
from acslam.scenario import Scenario
from acslam.server import Server, ServerStatus
from acslam.sim.simulator import Simulator
from acslam.trajectory import write_tum
from acslam.worlds.mapio import save_map

EXPLORED_SAMPLE_PERIOD_S = 1.0


def robot_name(robot_id: int) -> str:
    return f"robot_{robot_id}"


def resolved_config(scenario: Scenario) -> dict:
    """The scenario exactly as run: every default filled in, the team made explicit."""
    resolved = scenario.config.model_dump(mode="json")
    resolved["robots"]["count"] = scenario.robot_count
    resolved["robots"]["starts"] = scenario.starts.tolist()
    return resolved


def run_exploration(
    scenario: Scenario,
    out_dir: Path,
    max_time_s: float,
    on_progress: Callable[[ServerStatus, float], None] | None = None,
) -> dict:
    """Explore ``scenario`` until done or ``max_time_s``; returns the metrics written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "config.yaml").write_text(yaml.safe_dump(resolved_config(scenario), sort_keys=False))
    config = scenario.config
    sim = Simulator(
        scenario.world,
        scenario.starts,
        scenario.landmarks,
        config.robots,
        config.sensors,
        config.sim,
        config.seed,
    )
    server = Server(config, scenario.starts, scenario.world.spec)
    substeps = max(1, round(config.algorithms.planning.control_period_s / config.sim.dt_s))
    explored_history: list[tuple[float, float]] = []
    cell_area_m2 = scenario.world.spec.resolution_m**2
    next_sample_s = 0.0
    reason = "time limit"
    started = time.perf_counter()
    messages: list[RobotMessage] = []
    try:
        while sim.time_s < max_time_s - 1e-9:
            commands = server.step(messages, sim.time_s)
            if server.finished:
                reason = "explored"
                break
            messages = sim.step(commands)
            for _ in range(substeps - 1):
                messages += sim.step()
            if sim.time_s >= next_sample_s:
                known = server.team_map.global_grid.known_mask()
                explored_history.append((sim.time_s, float(known.sum()) * cell_area_m2))
                next_sample_s += EXPLORED_SAMPLE_PERIOD_S
                if on_progress is not None:
                    on_progress(server.status(sim.time_s), explored_history[-1][1])
    except AcslamError as exc:
        reason = f"error: {exc}"
    except Exception as exc:  # the run's products must survive any failure
        reason = f"error: {type(exc).__name__}: {exc}"
        (out_dir / "error.txt").write_text(traceback.format_exc())
    wall_time_s = time.perf_counter() - started
    record = _record(scenario, server, sim, explored_history)
    metrics = _metrics(scenario, server, sim, record, reason, wall_time_s)
    _write_outputs(out_dir, scenario, record)
    (out_dir / "metrics.json").write_text(json.dumps(metrics, indent=2, allow_nan=True))
    write_report(out_dir, record, metrics)
    return metrics


def _record(
    scenario: Scenario, server: Server, sim: Simulator, explored_history: list
) -> RunRecord:
    """The arrays figures and metrics are made from, saved so reports can be rebuilt."""
    world = scenario.world
    count = scenario.robot_count
    estimated = [server.slam.trajectory(i) for i in range(count)]
    truth = [sim.ground_truth.trajectory(i) for i in range(count)]
    return RunRecord(
        spec=world.spec,
        true_occupied=world.occupied,
        reachable=world.reachable_free(*scenario.starts[0, :2], scenario.config.robots.radius_m),
        estimated_values=server.team_map.global_grid.to_occupancy_values(),
        robot_known=np.stack([server.team_map.robot_grid(i).known_mask() for i in range(count)]),
        estimated_trajectories=[np.column_stack([s, p]) for s, p in estimated],
        true_trajectories=truth,
        explored_history=np.array(explored_history).reshape(-1, 2),
        landmarks_true=scenario.landmarks,
        landmarks_estimated=server.slam.landmarks(),
    )


def _metrics(
    scenario: Scenario,
    server: Server,
    sim: Simulator,
    record: RunRecord,
    reason: str,
    wall_time_s: float,
) -> dict:
    count = scenario.robot_count
    names = [robot_name(i) for i in range(count)]
    finish = {
        names[i]: (
            task.idle_since_s
            if reason == "explored" and task.idle_since_s is not None
            else sim.time_s
        )
        for i, task in enumerate(server.tasks)
    }
    localization = {}
    for i, name in enumerate(names):
        est, true = record.estimated_trajectories[i], record.true_trajectories[i]
        localization[name] = localization_errors(est[:, 0], est[:, 1:], true[:, 0], true[:, 1:])
    cell_area_m2 = scenario.world.spec.resolution_m**2
    known = record.estimated_values != -1
    reachable = record.reachable
    true_xy = np.stack([t[:, 1:3] for t in record.true_trajectories], axis=1)
    if count > 1:
        gaps = np.linalg.norm(true_xy[:, :, None] - true_xy[:, None], axis=-1)
        min_distance = float(gaps[:, ~np.eye(count, dtype=bool)].min())
    else:
        min_distance = math.inf
    collisions = sim.ground_truth.collisions
    samples = server.timer.samples
    cycle = np.array(samples.get("cycle", [0.0]))
    per_module = {
        module: {"mean": 1000 * float(np.mean(v)), "p95": 1000 * float(np.percentile(v, 95))}
        for module, v in samples.items()
        if module != "cycle"
    }
    return {
        "scenario": scenario.config.name,
        "robots": count,
        "seed": scenario.config.seed,
        "planner": scenario.config.algorithms.planning.local_planner,
        "allocator": scenario.config.algorithms.allocation.method,
        "completed": reason == "explored",
        "reason": reason,
        "sim_time_s": sim.time_s,
        "wall_time_s": wall_time_s,
        "real_time_factor": sim.time_s / max(wall_time_s, 1e-9),
        "timing": timing(finish),
        "localization": localization,
        "coverage": {
            **coverage_by_combination(
                dict(zip(names, record.robot_known, strict=True)), cell_area_m2
            ),
            "explored_fraction_of_reachable": float((known & reachable).sum() / reachable.sum()),
        },
        "mapping": confusion_rates(record.true_occupied, record.estimated_values),
        "safety": {
            "obstacle_collisions": int(collisions[:, 0].sum()),
            "robot_collisions": int(collisions[:, 1].sum()),
            "min_robot_distance_m": min_distance,
            "stuck_events": int(sum(task.recovery.count for task in server.tasks)),
        },
        "server_cycle_ms": {
            "mean": 1000 * float(np.mean(cycle)),
            "p95": 1000 * float(np.percentile(cycle, 95)),
            **per_module,
        },
    }


def _write_outputs(out_dir: Path, scenario: Scenario, record: RunRecord) -> None:
    save_map(out_dir / "map", record.estimated_values, scenario.world.spec)
    for i in range(scenario.robot_count):
        est, true = record.estimated_trajectories[i], record.true_trajectories[i]
        write_tum(
            out_dir / "trajectories" / f"{robot_name(i)}.estimated.tum", est[:, 0], est[:, 1:]
        )
        write_tum(
            out_dir / "trajectories" / f"{robot_name(i)}.groundtruth.tum", true[:, 0], true[:, 1:]
        )
    record.save(out_dir / "run.npz")
