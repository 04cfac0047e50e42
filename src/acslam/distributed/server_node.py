"""``acslam serve``: the server in wall-clock time, talking to robots over Zenoh.

Each control period the server steps on whatever arrived since the last one (late messages
are simply used late), sends commands and publishes its status. Mapping, the map update,
the decisions and loop-closure matching run beside that loop
(:class:`~acslam.pipeline.jobs.BackgroundJobs`), so a slow one delays the map, new goals
or closures, not the robots' commands. It starts once every robot has sent a heartbeat, at
the pose the heartbeat reports: the start pose on a fresh run, the robot's own
dead-reckoned pose after a server restart (there is no persisted state; the restarted
server maps afresh from there). A robot whose heartbeats stop for ``heartbeat_timeout_s``
is marked lost (:meth:`~acslam.pipeline.server.Server.mark_lost`) and ignored from then
on.

The run folder is written like an in-process run's (:func:`acslam.runner.finish_run`);
ground truth comes from the robots' truth side channel, which only this evaluation
reads, never the :class:`~acslam.pipeline.server.Server`. Times are seconds since the server
started; robot stamps are the robots' own simulated clocks, which start when they first
hear the server, so the two agree to a few milliseconds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from acslam.pipeline.frames import FramedServer
from acslam.pipeline.jobs import BackgroundJobs
from acslam.pipeline.server import Server
from acslam.runner import (
    NO_HOOKS,
    RunHooks,
    RunLog,
    TruthLog,
    finish_run,
    robot_name,
    run_loop,
    start_run_folder,
)
from acslam.scenario import Scenario
from acslam.sources.zenoh import ZenohSource
from acslam.transport.codec import StatusBeacon, TruthBatch
from acslam.transport.zenoh_link import ZenohServerEndpoint, open_session

FINAL_STATUS_REPEATS = 5


@dataclass(frozen=True)
class ServeOptions:
    """Timing of the server node (wall-clock seconds)."""

    heartbeat_timeout_s: float = 2.0
    startup_timeout_s: float = 60.0


def serve(
    scenario: Scenario,
    listen: str,
    out_dir: Path,
    max_time_s: float,
    *,
    options: ServeOptions | None = None,
    hooks: RunHooks = NO_HOOKS,
) -> dict:
    """Serve robots on ``listen`` until explored, all lost, or ``max_time_s``; returns
    the metrics written to ``out_dir``."""
    options = options or ServeOptions()
    session = open_session(listen=listen)
    out_dir = start_run_folder(out_dir, scenario)
    count = scenario.robot_count
    try:
        endpoint = ZenohServerEndpoint(session, count)
        starts, missing = _wait_for_robots(endpoint, scenario, options.startup_timeout_s)
        server: Server | FramedServer
        if scenario.config.robots.relative_starts == "unknown":
            # The heartbeats' start poses only score the run: the server is not told them.
            server = FramedServer(scenario.config, count, scenario.world.spec, BackgroundJobs)
            true_starts = starts
        else:
            server = Server(scenario.config, starts, scenario.world.spec, BackgroundJobs())
            true_starts = None
        for robot in missing:
            server.mark_lost(robot, 0.0)
            endpoint.ignore(robot)
        log = RunLog(scenario.world.spec, server.snapshot(0.0), hooks.on_progress, true_starts)
        endpoint.reset_stats()
        period_s = scenario.config.algorithms.planning.control_period_s
        source = ZenohSource(endpoint, period_s, options.heartbeat_timeout_s)
        try:
            reason, wall_time_s = run_loop(
                server, source, log, max_time_s=max_time_s, out_dir=out_dir, on_step=hooks.on_step
            )
        finally:
            server.close()
        now_s = source.time_s
        lost = log.last.lost
        for _ in range(FINAL_STATUS_REPEATS):
            endpoint.publish_status(StatusBeacon(now_s, True, tuple(lost)))
            time.sleep(0.1)
        truth = _truth_log(endpoint.truth(), scenario)
        extra = {
            "distributed": {
                "lost_robots": {robot_name(i): t for i, t in sorted(lost.items())},
                "transport": endpoint.stats_summary(),
            }
        }
        return finish_run(
            out_dir, scenario, log, truth,
            reason=reason, wall_time_s=wall_time_s, time_s=now_s, extra=extra,
        )  # fmt: skip
    finally:
        session.close()


def _wait_for_robots(
    endpoint: ZenohServerEndpoint, scenario: Scenario, timeout_s: float
) -> tuple[np.ndarray, list[int]]:
    """Start poses from every robot's first heartbeat; robots not heard in time are
    missing (they start lost, at their scenario start)."""
    deadline = time.monotonic() + timeout_s
    heard = endpoint.heartbeats()
    while len(heard) < scenario.robot_count and time.monotonic() < deadline:
        time.sleep(0.05)
        heard = endpoint.heartbeats()
    starts = scenario.starts.copy()
    for robot, (_, beat) in heard.items():
        starts[robot] = beat.pose
    return starts, [i for i in range(scenario.robot_count) if i not in heard]


def _truth_log(batches: dict[int, list[TruthBatch]], scenario: Scenario) -> TruthLog:
    """Each robot's true trajectory as received on the truth channel, in stamp order; a
    robot never heard stays at its start."""
    trajectories, collisions = [], np.zeros((scenario.robot_count, 2), dtype=np.int64)
    for robot in range(scenario.robot_count):
        received = batches.get(robot, [])
        if not received:
            trajectories.append(np.array([[0.0, *scenario.starts[robot]]]))
            continue
        rows = np.vstack([np.column_stack([b.stamps, b.poses]) for b in received])
        _, unique = np.unique(rows[:, 0], return_index=True)
        trajectories.append(rows[unique])
        collisions[robot] = received[-1].collisions
    return TruthLog(trajectories, collisions)
