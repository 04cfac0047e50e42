"""Closes the loop of thesis Fig. 4.2 on the simulated clock and writes the run folder.

Every control period the server gets the messages the robots sent since the last one
(through the in-process transport) and answers with velocity commands; the simulator
advances until the next period. The run reads the server only through the
snapshot each step returns (:class:`RunLog`). The scoring and writing half
(:func:`finish_run`) is shared with the distributed run, which gets its ground truth over
the wire instead.
Ground truth is read only after the run, for the metrics. Whatever happens, the run folder
gets ``config.yaml`` first and ``metrics.json`` last, with ``completed`` and ``reason``,
so a failed, timed-out or stopped run (SIGINT, SIGTERM: :mod:`acslam.stop`) keeps what it
produced; a run too short for any estimate still gets its ``metrics.json``.
"""

from __future__ import annotations

import time
import traceback
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from acslam import stop
from acslam.errors import AcslamError
from acslam.eval.frames import (
    frame_origins,
    merge_metrics,
    placed_poses,
    world_known,
    world_values,
    write_merge_figures,
)
from acslam.eval.metrics import (
    confusion_rates,
    coverage_by_combination,
    exploration_times,
    explored_areas,
    localization_errors,
    team_alignment,
    timing,
)
from acslam.eval.report import RunRecord, write_report
from acslam.files import write_text, write_yaml
from acslam.geometry import transform_points
from acslam.grid import UNKNOWN, GridSpec
from acslam.messages import RobotMessage
from acslam.pipeline.frames import FramedServer, sighting_reach_m
from acslam.pipeline.server import Server
from acslam.pipeline.snapshot import Snapshot
from acslam.provenance import write_metrics
from acslam.scenario import Scenario
from acslam.sim.simulator import Simulator
from acslam.sources import DataSource
from acslam.sources.simulated import SimulatedSource
from acslam.trajectory import write_tum
from acslam.worlds.mapio import save_map

EXPLORED_SAMPLE_PERIOD_S = 1.0


ProgressHook = Callable[[Snapshot, float, float], None]
"""Called with the snapshot, the simulated time and the explored m^2 once per second."""
StepHook = Callable[[Snapshot, list[RobotMessage]], None]
"""Called with every step's snapshot and that step's messages (live views)."""
FinishHook = Callable[["TruthLog"], None]
"""Called with the ground truth (which no hook sees during the run) once an in-process run
has written its folder."""


@dataclass(frozen=True)
class RunHooks:
    """What a caller watches of a run, in process or served."""

    on_progress: ProgressHook | None = None
    on_step: StepHook | None = None
    on_finish: FinishHook | None = None


NO_HOOKS = RunHooks()


def robot_name(robot_id: int) -> str:
    return f"robot_{robot_id}"


def start_run_folder(out_dir: Path, scenario: Scenario) -> Path:
    """Create the run folder and write its ``config.yaml`` first, before anything can
    fail: whatever happens next, the folder says what was run."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_yaml(out_dir / "config.yaml", resolved_config(scenario))
    return out_dir


def resolved_config(scenario: Scenario) -> dict:
    """The scenario exactly as run: every default filled in, the team made explicit."""
    resolved = scenario.config.model_dump(mode="json")
    resolved["robots"]["count"] = scenario.robot_count
    resolved["robots"]["starts"] = scenario.starts.tolist()
    return resolved


def run_loop(
    server: Server | FramedServer,
    source: DataSource,
    log: RunLog,
    *,
    max_time_s: float,
    out_dir: Path,
    on_step: StepHook | None = None,
) -> tuple[str, float]:
    """Step the server once per control period until explored, every robot lost, an
    error, a stopping signal (:func:`acslam.stop.requested`) or ``max_time_s``; returns
    the reason and the wall seconds it took. Any exception ends the run with its reason
    (:func:`failure_reason`), so the run's products survive it."""
    reason = "time limit"
    started = time.perf_counter()
    try:
        while not source.finished and source.time_s < max_time_s - 1e-9:
            stopped = stop.requested()
            if stopped is not None:
                reason = stopped
                break
            for robot in source.newly_lost():
                server.mark_lost(robot, source.time_s)
            messages = source.receive()
            snapshot = server.step(messages, source.time_s)
            log.record(snapshot)
            if len(snapshot.lost) == len(snapshot.poses):
                reason = "all robots lost"
                break
            source.deliver(snapshot)
            if on_step is not None:
                on_step(snapshot, messages)
            if snapshot.finished:
                reason = "explored"
                break
            source.advance()
            log.sample_explored(source.time_s)
    except Exception as exc:
        reason = failure_reason(exc, out_dir)
    return reason, time.perf_counter() - started


def run_exploration(
    scenario: Scenario,
    out_dir: Path,
    max_time_s: float,
    hooks: RunHooks = NO_HOOKS,
) -> dict:
    """Explore ``scenario`` until done or ``max_time_s``; returns the metrics written."""
    out_dir = start_run_folder(out_dir, scenario)
    config = scenario.config
    sim = scenario.simulator()
    server: Server | FramedServer
    if config.robots.relative_starts == "unknown":
        server = FramedServer(config, scenario.robot_count, scenario.world.spec)
    else:
        server = Server(config, scenario.starts, scenario.world.spec)
    substeps = max(1, round(config.algorithms.planning.control_period_s / config.sim.dt_s))
    log = RunLog(scenario.world.spec, server.snapshot(0.0), hooks.on_progress, scenario.starts)
    source = SimulatedSource(sim, substeps)
    reason, wall_time_s = run_loop(
        server, source, log, max_time_s=max_time_s, out_dir=out_dir, on_step=hooks.on_step
    )
    truth = TruthLog.of_simulator(sim)
    metrics = finish_run(
        out_dir, scenario, log, truth, reason=reason, wall_time_s=wall_time_s, time_s=sim.time_s
    )
    if hooks.on_finish is not None:
        hooks.on_finish(truth)
    return metrics


def failure_reason(exc: Exception, out_dir: Path) -> str:
    """The ``reason`` of a run stopped by ``exc``: an AcslamError names the problem itself;
    anything else is a bug, so its traceback goes to ``out_dir/error.txt``."""
    if isinstance(exc, AcslamError):
        return f"error: {exc}"
    write_text(out_dir / "error.txt", traceback.format_exc())
    return f"error: {type(exc).__name__}: {exc}"


@dataclass
class RunLog:
    """What a run keeps of the server's snapshots: the latest one, every stage's timings
    (``[simulated time, wall seconds]`` each time it ran), every robot's pose as the
    server used it at each step (``[time, x, y, theta]``), and the explored area once per
    simulated second (reported as progress).

    With unknown relative starts the server's frames are placed in the world by the
    robots' true starts (``true_starts``; scoring only, the server never sees them)."""

    spec: GridSpec
    last: Snapshot
    on_progress: ProgressHook | None = None
    true_starts: np.ndarray | None = None
    timings_s: dict[str, list[tuple[float, float]]] = field(
        default_factory=lambda: defaultdict(list)
    )
    explored_history: list[tuple[float, float]] = field(default_factory=list)
    online_poses: list[np.ndarray] = field(default_factory=list)
    at_explored: Snapshot | None = None
    """The snapshot of the step the team had nothing left to explore (before a patrol)."""
    _next_sample_s: float = 0.0

    def record(self, snapshot: Snapshot) -> None:
        self.last = snapshot
        if self.at_explored is None and snapshot.explored_s is not None:
            self.at_explored = snapshot
        for stage, seconds in snapshot.timings_s.items():
            self.timings_s[stage].append((snapshot.time_s, seconds))
        poses = np.asarray(snapshot.poses, dtype=float)
        if snapshot.frames:
            assert self.true_starts is not None
            origins = frame_origins(snapshot, self.true_starts)
            poses = np.vstack([placed_poses(origins[i], pose) for i, pose in enumerate(poses)])
        self.online_poses.append(np.column_stack([np.full(len(poses), snapshot.time_s), poses]))

    def sample_explored(self, time_s: float) -> None:
        if time_s < self._next_sample_s:
            return
        if self.last.frames:
            assert self.true_starts is not None
            known = world_known(self.last, self.true_starts, self.spec)
        else:
            known = self.last.map.known_mask()
        self.explored_history.append((time_s, float(known.sum()) * self.spec.resolution_m**2))
        self._next_sample_s += EXPLORED_SAMPLE_PERIOD_S
        if self.on_progress is not None:
            self.on_progress(self.last, time_s, self.explored_history[-1][1])


@dataclass(frozen=True)
class TruthLog:
    """The ground truth a run is scored against: ``[t, x, y, theta]`` rows per robot (none
    for a real robot) and (N, 2) contact counts (walls, robots), None where unknown."""

    trajectories: list[np.ndarray]
    collisions: np.ndarray | None

    @classmethod
    def of_simulator(cls, sim: Simulator) -> TruthLog:
        gt = sim.ground_truth
        return cls([gt.trajectory(i) for i in range(sim.robot_count)], gt.collisions)


def finish_run(
    out_dir: Path,
    scenario: Scenario,
    log: RunLog,
    truth: TruthLog,
    *,
    reason: str,
    wall_time_s: float,
    time_s: float,
    extra: dict | None = None,
) -> dict:
    """Score a finished run from its last snapshot and write its folder; ``extra`` adds
    metric sections, and ``provenance`` says what produced them. Returns the metrics as
    written: a figure that has no value (no other robot to keep a distance from, a rate
    without cells) is None, JSON's ``null``."""
    if log.last.frames:
        names = [robot_name(i) for i in range(scenario.robot_count)]
        config = scenario.config
        reach_m = sighting_reach_m(config.sensors.lidar.range_max_m, config.robots.radius_m)
        unknown_starts = merge_metrics(
            log.last, scenario.starts, truth.trajectories, names, scenario.world, reach_m
        )
        extra = {**(extra or {}), "unknown_starts": unknown_starts}
        write_merge_figures(out_dir, log.last.merges)
    record = _record(scenario, log, truth)
    metrics = _metrics(scenario, log, truth, record, reason, wall_time_s, time_s)
    _write_outputs(out_dir, scenario, record)
    metrics = write_metrics(out_dir, {**metrics, **(extra or {})})
    write_report(out_dir, record, metrics)
    return metrics


def _record(scenario: Scenario, log: RunLog, truth_log: TruthLog) -> RunRecord:
    """The arrays figures and metrics are made from, saved so reports can be rebuilt."""
    world = scenario.world
    count = scenario.robot_count
    last = log.last
    trajectories = [np.column_stack(last.localization.trajectory(i)) for i in range(count)]
    landmarks = last.localization.landmarks()
    if last.frames:  # each frame placed in the world by its first robot's true start
        origins = frame_origins(last, scenario.starts)
        trajectories = [
            np.column_stack([t[:, 0], placed_poses(origins[i], t[:, 1:])])
            for i, t in enumerate(trajectories)
        ]
        landmarks = np.vstack(
            [_placed_landmarks(origins[v.robot_ids[0]], v.snapshot) for v in last.frames]
        )
    return RunRecord(
        spec=world.spec,
        true_occupied=world.occupied,
        reachable=world.reachable_free(*scenario.starts[0, :2], scenario.config.robots.radius_m),
        estimated_values=world_values(last, scenario.starts, world.spec),
        robot_known=np.stack(
            [world_known(last, scenario.starts, world.spec, i) for i in range(count)]
        ),
        estimated_trajectories=trajectories,
        true_trajectories=truth_log.trajectories,
        explored_history=np.array(log.explored_history).reshape(-1, 2),
        landmarks_true=scenario.landmarks,
        landmarks_estimated=landmarks,
        stage_names=np.array(list(log.timings_s), dtype=str),
        stage_timings=[np.array(samples).reshape(-1, 2) for samples in log.timings_s.values()],
        control_period_s=scenario.config.algorithms.planning.control_period_s,
        online_trajectories=list(np.stack(log.online_poses, axis=1))
        if log.online_poses
        else [np.zeros((0, 4)) for _ in range(count)],
    )


def _placed_landmarks(origin: np.ndarray, snapshot: Snapshot) -> np.ndarray:
    """A frame's (M, 3) landmarks, in the world."""
    landmarks = snapshot.localization.landmarks().reshape(-1, 3)
    return np.column_stack([transform_points(origin, landmarks[:, :2]), landmarks[:, 2]])


def _timing_statistics_ms(samples_ms: np.ndarray) -> dict[str, float]:
    """Mean, p95, p99 and maximum: a stage that runs in few cycles (allocation) can be
    slow where a whole-cycle p95 does not show it."""
    return {
        "mean": float(np.mean(samples_ms)),
        "p95": float(np.percentile(samples_ms, 95)),
        "p99": float(np.percentile(samples_ms, 99)),
        "max": float(np.max(samples_ms)),
    }


def _mapping(scenario: Scenario, last: Snapshot, record: RunRecord, alignment: dict | None) -> dict:
    """The map scored cell by cell against the truth (Table 5.4), and its accuracy once
    moved by the team's alignment (``aligned_accuracy``, None without ground truth): a
    map turned as a whole by a heading error made early scores low however right it is
    inside (IPA office_f with unknown starts, seed 0: 88.3 % in the start frame, 97.1 %
    aligned)."""
    mapping = confusion_rates(record.true_occupied, record.estimated_values)
    aligned = None
    if alignment is not None:
        motion = np.array([*alignment["translation_m"], alignment["rotation_rad"]])
        values = world_values(last, scenario.starts, scenario.world.spec, motion)
        aligned = confusion_rates(record.true_occupied, values)["accuracy"]
    return {**mapping, "aligned_accuracy": aligned}


def _metrics(
    scenario: Scenario,
    log: RunLog,
    truth: TruthLog,
    record: RunRecord,
    reason: str,
    wall_time_s: float,
    time_s: float,
) -> dict:
    count = scenario.robot_count
    names = [robot_name(i) for i in range(count)]
    last = log.last
    # A patrol after exploring does not change when each robot was done exploring.
    explored = log.at_explored or last
    done_s = exploration_times(
        reason == "explored" or log.at_explored is not None,
        explored.idle_since_s,
        explored.lost,
        time_s,
    )
    localization, online_localization = {}, {}
    scored = []
    for i, name in enumerate(names):
        est, true = record.estimated_trajectories[i], record.true_trajectories[i]
        online = record.online_trajectories[i]
        # A real robot has no ground truth to be scored against, a run shorter than a
        # keyframe has no estimate within the truth's span, and a served run's truth may
        # start after its server's first steps.
        if _within(est[:, 0], true):
            scored.append((est[:, 0], est[:, 1:], true[:, 0], true[:, 1:]))
            localization[name] = localization_errors(*scored[-1])
        if _within(online[:, 0], true):
            online_localization[name] = localization_errors(
                online[:, 0], online[:, 1:], true[:, 0], true[:, 1:]
            )
    alignment = team_alignment(scored) if scored else None
    cell_area_m2 = scenario.world.spec.resolution_m**2
    if count > 1 and all(len(true) for true in record.true_trajectories):
        true_xy = _common_clock_xy(record.true_trajectories)
        gaps = np.linalg.norm(true_xy[:, :, None] - true_xy[:, None], axis=-1)
        min_distance: float | None = float(gaps[:, ~np.eye(count, dtype=bool)].min())
    else:  # one robot keeps no distance to another; a real team has no ground truth
        min_distance = None
    collisions = truth.collisions
    stages_ms = {
        str(stage): 1000 * samples[:, 1]
        for stage, samples in zip(record.stage_names, record.stage_timings, strict=True)
    }
    cycle_ms = stages_ms.pop("cycle", np.zeros(1))
    algorithms = scenario.config.algorithms
    return {
        "scenario": scenario.config.name,
        "robots": count,
        "seed": scenario.config.seed,
        "planner": algorithms.local_planner.name,
        "allocator": algorithms.allocator.name,
        "completed": reason == "explored",
        "reason": reason,
        "sim_time_s": time_s,
        "wall_time_s": wall_time_s,
        "real_time_factor": time_s / max(wall_time_s, 1e-9),
        "timing": timing(dict(zip(names, done_s, strict=True))),
        "localization": localization,
        "online_localization": online_localization,
        "team_alignment": alignment,
        "coverage": {
            **coverage_by_combination(
                dict(zip(names, record.robot_known, strict=True)), cell_area_m2
            ),
            **explored_areas(record.estimated_values != UNKNOWN, record.reachable, cell_area_m2),
        },
        "mapping": _mapping(scenario, last, record, alignment),
        "waste": record.waste(names),
        "safety": {
            "obstacle_collisions": None if collisions is None else int(collisions[:, 0].sum()),
            "robot_collisions": None if collisions is None else int(collisions[:, 1].sum()),
            "min_robot_distance_m": min_distance,
            "stuck_events": int(sum(last.stuck_events)),
        },
        "server_cycle_ms": {
            **_timing_statistics_ms(cycle_ms),
            "control_period_ms": 1000 * algorithms.planning.control_period_s,
            **{stage: _timing_statistics_ms(ms) for stage, ms in stages_ms.items()},
        },
        **_patrol_metrics(algorithms.server.patrol_s, log.at_explored, record, time_s),
    }


def _within(stamps: np.ndarray, true: np.ndarray) -> bool:
    """Whether some of ``stamps`` fall within the span of the ``[t, ...]`` truth rows."""
    return len(true) >= 2 and bool(np.any((stamps >= true[0, 0]) & (stamps <= true[-1, 0])))


PHASE_SHARE = 0.1
"""A phase's cost is compared between its first and its last tenth."""


def tenths_p95_ms(samples: np.ndarray, start_s: float, end_s: float) -> tuple[float, float] | None:
    """p95 in ms of a stage's ``[simulated time s, wall s]`` samples over the first and the
    last ``PHASE_SHARE`` of ``[start_s, end_s]``; None if either holds none."""
    tenth_s = PHASE_SHARE * (end_s - start_s)
    first = samples[(samples[:, 0] >= start_s) & (samples[:, 0] < start_s + tenth_s), 1]
    last = samples[samples[:, 0] >= end_s - tenth_s, 1]
    if not (len(first) and len(last)):
        return None
    return 1000 * float(np.percentile(first, 95)), 1000 * float(np.percentile(last, 95))


def _patrol_metrics(
    patrol_s: float, at_explored: Snapshot | None, record: RunRecord, end_s: float
) -> dict:
    """Whether a cycle gets dearer as the trajectory grows over a map that no longer does:
    each stage's p95 over the first and the last tenth of the patrol, and their ratio.
    Nothing when the scenario does not patrol or the run ended before exploring."""
    if patrol_s <= 0 or at_explored is None or end_s <= at_explored.time_s:
        return {}
    start_s = at_explored.time_s
    stages = {}
    for stage, samples in zip(record.stage_names, record.stage_timings, strict=True):
        tenths = tenths_p95_ms(samples, start_s, end_s)
        if tenths is not None:
            first_ms, last_ms = tenths
            stages[str(stage)] = {
                "first_tenth_p95_ms": first_ms,
                "last_tenth_p95_ms": last_ms,
                "growth": last_ms / first_ms if first_ms > 0 else None,
            }
    return {"patrol": {"start_s": start_s, "end_s": end_s, "stages": stages}}


def _common_clock_xy(trajectories: list[np.ndarray]) -> np.ndarray:
    """(T, N, 2) positions of all robots at shared times.

    In-process runs log every robot at every step; robots of a distributed run log on
    their own clocks (and a lost one stops early, standing where it was), so they are
    interpolated onto the longest log's stamps.
    """
    if len({len(t) for t in trajectories}) == 1:
        return np.stack([t[:, 1:3] for t in trajectories], axis=1)
    stamps = max(trajectories, key=len)[:, 0]
    return np.stack(
        [
            np.column_stack([np.interp(stamps, t[:, 0], t[:, k]) for k in (1, 2)])
            for t in trajectories
        ],
        axis=1,
    )


def _write_outputs(out_dir: Path, scenario: Scenario, record: RunRecord) -> None:
    save_map(out_dir / "map", record.estimated_values, scenario.world.spec)
    for i in range(scenario.robot_count):
        est, true = record.estimated_trajectories[i], record.true_trajectories[i]
        write_tum(
            out_dir / "trajectories" / f"{robot_name(i)}.estimated.tum", est[:, 0], est[:, 1:]
        )
        if len(true):
            write_tum(
                out_dir / "trajectories" / f"{robot_name(i)}.groundtruth.tum",
                true[:, 0],
                true[:, 1:],
            )
    record.save(out_dir / "run.npz")
