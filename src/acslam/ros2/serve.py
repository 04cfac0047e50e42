"""``acslam serve --ros2``: the server in wall-clock time for ROS 2 robots.

The server waits until each robot's odometry, a scan and the laser mount joining them
have arrived (robots not ready by ``startup_timeout_s`` start lost), starts each robot's
estimate at the scenario's start pose (with ``robots.relative_starts: unknown``, at the
origin of a frame of its own, to be merged as the data allows: the start poses then only
place the frames for scoring), then runs the same loop as every other run
(:func:`acslam.runner.run_loop`), with the map update and the decisions beside it
(:class:`~acslam.pipeline.jobs.BackgroundJobs`). Whatever ends the run, every robot is
sent zero velocity. The run folder is written as an in-process run's; the ground truth comes from
the robots' ``ground_truth`` topics, or is absent (a real team), and then the run is
scored on what needs no truth.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import zenoh

from acslam import runner
from acslam.errors import TransportError
from acslam.geometry import compose
from acslam.pipeline.frames import FramedServer
from acslam.pipeline.jobs import BackgroundJobs
from acslam.pipeline.server import Server
from acslam.ros2.node import Ros2Node, Ros2Options, open_ros2_session
from acslam.ros2.source import Ros2Source, Ros2Topics
from acslam.scenario import Scenario

SERVER_NODE_NAME = "acslam_server"


@dataclass(frozen=True)
class Ros2ServeOptions:
    """The network side of a ROS 2 served run (seconds are wall-clock)."""

    namespaces: tuple[str, ...]
    ros2: Ros2Options = field(default_factory=Ros2Options)
    connect: tuple[str, ...] = ()  # "tcp/HOST:PORT" for all robots, or "ns=tcp/HOST:PORT"
    listen: str | None = None
    topics: Ros2Topics = field(default_factory=Ros2Topics)
    global_tf: bool = False
    laser_mount: tuple[float, float, float] | None = None  # instead of tf_static
    lost_after_s: float = 2.0
    startup_timeout_s: float = 60.0


TruthSource = Callable[[Ros2Source], runner.TruthLog]


def topic_truth(source: Ros2Source) -> runner.TruthLog:
    """Ground truth from the robots' ``ground_truth`` topics (simulated robots publish
    one; a real robot's trajectory is empty, and the run is scored on what needs no
    truth). Contacts are not on the wire."""
    return runner.TruthLog(source.truth(), None)


def serve_ros2(
    scenario: Scenario,
    out_dir: Path,
    max_time_s: float,
    options: Ros2ServeOptions,
    *,
    truth: TruthSource = topic_truth,
    hooks: runner.RunHooks = runner.NO_HOOKS,
) -> dict:
    """Serve ROS 2 robots until explored, all lost, or ``max_time_s``; returns the
    metrics written to ``out_dir``."""
    out_dir = runner.start_run_folder(out_dir, scenario)
    sessions, nodes = _open_nodes(options)
    try:
        period_s = scenario.config.algorithms.planning.control_period_s
        source = Ros2Source(
            nodes,
            list(options.namespaces),
            scenario.world.spec,
            period_s=period_s,
            lost_after_s=options.lost_after_s,
            topics=options.topics,
            global_tf=options.global_tf,
            laser_mount=None if options.laser_mount is None else np.array(options.laser_mount),
        )
        try:
            mounts = _wait_until_ready(source, len(options.namespaces), options.startup_timeout_s)
            source.start(mounts)
            starts = scenario.starts.copy()
            for robot, mount in mounts.items():
                starts[robot] = compose(scenario.starts[robot], mount)
            server: Server | FramedServer
            if scenario.config.robots.relative_starts == "unknown":
                server = FramedServer(
                    scenario.config, len(starts), scenario.world.spec, BackgroundJobs
                )
            else:
                server = Server(scenario.config, starts, scenario.world.spec, BackgroundJobs())
            for robot in set(range(len(starts))) - set(mounts):
                server.mark_lost(robot, 0.0)
            # The starts place the frames of unknown starts for scoring only.
            log = runner.RunLog(
                scenario.world.spec, server.snapshot(0.0), hooks.on_progress, starts
            )
            try:
                reason, wall_time_s = runner.run_loop(
                    server, source, log,
                    max_time_s=max_time_s, out_dir=out_dir, on_step=hooks.on_step,
                )  # fmt: skip
            finally:
                server.close()
        finally:
            source.stop()
        extra = {"ros2": {"robots": list(options.namespaces), **source.statistics()}}
        # Scored at the lasers' starts: the poses the server estimates (and, with unknown
        # starts, its frames' origins) are the lasers'.
        return runner.finish_run(
            out_dir, replace(scenario, starts=starts), log, truth(source),
            reason=reason, wall_time_s=wall_time_s, time_s=source.time_s, extra=extra,
        )  # fmt: skip
    finally:
        for node in dict.fromkeys(nodes):
            node.close()
        for session in sessions:
            session.close()


def _open_nodes(options: Ros2ServeOptions) -> tuple[list[zenoh.Session], list[Ros2Node]]:
    """The sessions and, per robot, the node its topics go through: one session for the
    robots on a shared router (or connecting to this one, ``listen``), and one per robot
    router given as ``ns=ENDPOINT``."""
    per_robot = dict(item.split("=", 1) for item in options.connect if "=" in item)
    unknown = set(per_robot) - set(options.namespaces)
    if unknown:
        raise TransportError(f"--connect: no robot named {', '.join(sorted(unknown))}")
    shared = [item for item in options.connect if "=" not in item]
    sessions: list[zenoh.Session] = []

    def node(connect: list[str], listen: str | None = None) -> Ros2Node:
        session = open_ros2_session(connect=connect, listen=listen)
        sessions.append(session)
        return Ros2Node(session, SERVER_NODE_NAME, "/", options.ros2)

    own = {namespace: node([endpoint]) for namespace, endpoint in per_robot.items()}
    team = None
    if len(own) < len(options.namespaces):
        team = node(shared, options.listen)
    return sessions, [own.get(namespace) or team for namespace in options.namespaces]


def _wait_until_ready(source: Ros2Source, count: int, timeout_s: float) -> dict[int, np.ndarray]:
    deadline = time.monotonic() + timeout_s
    ready = source.ready()
    while len(ready) < count and time.monotonic() < deadline:
        time.sleep(0.05)
        ready = source.ready()
    return ready
