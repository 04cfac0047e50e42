"""Server.mark_lost in lock step: the lost robot gets no goal and zero velocity, the
others keep exploring and finish without it."""

from __future__ import annotations

from pathlib import Path

from acslam.pipeline.server import Server
from acslam.scenario import load_scenario


def test_lost_robot_is_dropped_from_allocation_and_finish(tiny_scenario: Path) -> None:
    scenario = load_scenario(tiny_scenario)
    config = scenario.config
    sim = scenario.simulator()
    server = Server(config, scenario.starts, scenario.world.spec)
    substeps = round(config.algorithms.planning.control_period_s / config.sim.dt_s)
    messages: list = []
    lost_at = None
    snapshot = server.snapshot(0.0)
    while sim.time_s < 100.0 and not snapshot.finished:
        if lost_at is None and snapshot.goals_m[2] is not None and sim.time_s >= 5.0:
            lost_at = sim.time_s
            server.mark_lost(2, sim.time_s)
            after = server.snapshot(sim.time_s)
            assert after.goals_m[2] is None and after.paths_m[2] is None
        snapshot = server.step(messages, sim.time_s)
        commands = list(snapshot.commands)
        if lost_at is not None:
            assert (commands[2].v, commands[2].omega) == (0.0, 0.0)
            assert snapshot.goals_m[2] is None
        # A lost robot's messages no longer arrive (it stands still on zero commands).
        messages = [m for m in sim.step(commands) if lost_at is None or m.robot_id != 2]
        for _ in range(substeps - 1):
            messages += [m for m in sim.step() if lost_at is None or m.robot_id != 2]
    assert lost_at is not None
    assert dict(snapshot.lost) == {2: lost_at}
    assert snapshot.finished  # robots 0 and 1 explored the rest; robot 2 never went idle
    assert snapshot.idle_since_s[2] is None
    known = snapshot.map.known_mask()
    reachable = scenario.world.reachable_free(*scenario.starts[0, :2], config.robots.radius_m)
    assert (known & reachable).sum() / reachable.sum() >= 0.95
