"""The server's heavy work: in the cycle that scheduled it in-process, beside the control
loop in served runs. An allocator that waits at a gate the test opens stands for one that
takes long."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np
import pytest
import yaml

from acslam.config import MappingConfig, StageParams
from acslam.exploration.allocation import Allocation
from acslam.grid import GridSpec
from acslam.mapping.costmap import Costmap
from acslam.mapping.occupancy import TeamMap
from acslam.pipeline.jobs import BackgroundJobs, InlineJobs, Jobs
from acslam.pipeline.registry import ALLOCATORS, MAPPERS
from acslam.pipeline.server import Server
from acslam.pipeline.snapshot import Snapshot
from acslam.pipeline.stages import Cells, Clusters, Goals
from acslam.scenario import Scenario, load_scenario
from acslam.slam.lidar_constraints import LidarConstraints
from acslam.sources.simulated import SimulatedSource

WAIT_S = 60.0
"""Longest wait for the worker thread (a bound against a hang, not a timing)."""


def with_stage(tiny_scenario: Path, kind: str, name: str) -> Scenario:
    """The tiny two-room scenario with the plugin ``name`` as its ``kind`` stage."""
    data = yaml.safe_load(tiny_scenario.read_text())
    data["algorithms"] = {kind: {"name": name}}
    path = tiny_scenario.parent / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_scenario(path)


class GatedParams(StageParams):
    name: Literal["gated"] = "gated"


class GatedAllocator:
    """Robot i takes cluster i (modulo their number), once ``gate`` is open; ``started``
    is set when an allocation with clusters begins, ``targets_m`` holds the targets each
    robot was given. ``error``: raised instead."""

    gate: ClassVar[threading.Event] = threading.Event()
    started: ClassVar[threading.Event] = threading.Event()
    error: ClassVar[Exception | None] = None
    targets_m: ClassVar[list[np.ndarray]] = []

    def __init__(self, params: GatedParams) -> None:
        self.params = params

    def allocate(
        self, robot_cells: Cells, clusters: Clusters, costmap: Costmap, current: Goals = None
    ) -> Allocation:
        count = len(robot_cells)
        if not clusters:
            return Allocation("gated", "in turn", (None,) * count, np.zeros((count, 0)))
        GatedAllocator.started.set()
        assert GatedAllocator.gate.wait(WAIT_S)
        if GatedAllocator.error is not None:
            raise GatedAllocator.error
        choice = tuple(i % len(clusters) for i in range(count))
        GatedAllocator.targets_m = [clusters[k].target_m for k in choice]
        return Allocation("gated", "in turn", choice, np.zeros((count, len(clusters))))


@pytest.fixture
def gated(tiny_scenario: Path) -> Iterator[Scenario]:
    """The tiny two-room scenario with the gated allocator, the gate shut."""
    ALLOCATORS.register("gated", GatedParams)(GatedAllocator)
    GatedAllocator.gate.clear()
    GatedAllocator.started.clear()
    GatedAllocator.error = None
    GatedAllocator.targets_m = []
    try:
        yield with_stage(tiny_scenario, "allocator", "gated")
    finally:
        GatedAllocator.gate.set()
        ALLOCATORS.unregister("gated")


class GatedMapParams(MappingConfig):
    name: Literal["gated-map"] = "gated-map"  # type: ignore[assignment]


class GatedMapper(TeamMap):
    """The log-odds map, whose scans after the first ``open_scans`` (None: all) wait at
    ``gate`` (a correction that takes long); ``waiting`` is set when one does."""

    made: ClassVar[list[GatedMapper]] = []
    gate: ClassVar[threading.Event] = threading.Event()
    waiting: ClassVar[threading.Event] = threading.Event()
    open_scans: ClassVar[int | None] = None
    handed: ClassVar[int] = 0

    def __init__(self, params: GatedMapParams, *, spec: GridSpec) -> None:
        super().__init__(params, spec=spec)
        GatedMapper.made.append(self)

    def add_scan(self, robot_id, scan_key, ranges, angles, pose, range_max_m=np.inf) -> None:
        GatedMapper.handed += 1
        if GatedMapper.open_scans is not None and GatedMapper.handed > GatedMapper.open_scans:
            GatedMapper.waiting.set()
            assert GatedMapper.gate.wait(WAIT_S)
        super().add_scan(robot_id, scan_key, ranges, angles, pose, range_max_m)


@pytest.fixture
def gated_map(tiny_scenario: Path) -> Iterator[Scenario]:
    """The tiny two-room scenario with the gated mapper, the gate shut."""
    MAPPERS.register("gated-map", GatedMapParams)(GatedMapper)
    GatedMapper.gate.clear()
    GatedMapper.waiting.clear()
    GatedMapper.handed = 0
    GatedMapper.open_scans = None
    GatedMapper.made.clear()
    try:
        yield with_stage(tiny_scenario, "mapper", "gated-map")
    finally:
        GatedMapper.gate.set()
        MAPPERS.unregister("gated-map")


class Loop:
    """The simulator and a server stepped one control period at a time."""

    def __init__(self, scenario: Scenario, jobs: Jobs) -> None:
        config = scenario.config
        substeps = round(config.algorithms.planning.control_period_s / config.sim.dt_s)
        self.source = SimulatedSource(scenario.simulator(), substeps)
        self.server = Server(config, scenario.starts, scenario.world.spec, jobs)

    def step(self) -> Snapshot:
        snapshot = self.server.step(self.source.receive(), self.source.time_s)
        self.source.deliver(snapshot)
        self.source.advance()
        return snapshot


def start_allocating(loop: Loop) -> None:
    """Step until an allocation with clusters to give has begun on the worker."""
    deadline = time.monotonic() + WAIT_S
    while not GatedAllocator.started.is_set():
        assert time.monotonic() < deadline
        loop.step()
        GatedAllocator.started.wait(0.01)


def test_inline_jobs_decide_in_the_cycle_that_scheduled_them(gated: Scenario) -> None:
    GatedAllocator.gate.set()
    loop = Loop(gated, InlineJobs())
    snapshot = loop.step()
    while not (snapshot.clusters and "allocation" in snapshot.timings_s):
        assert snapshot.time_s < 10.0
        snapshot = loop.step()
    # The first allocation with clusters to give: its goals are in the same cycle.
    assert len(GatedAllocator.targets_m) == len(snapshot.goals_m)
    for goal, target in zip(snapshot.goals_m, GatedAllocator.targets_m, strict=True):
        np.testing.assert_array_equal(goal, target)


def test_a_slow_allocation_does_not_hold_back_the_control_loop(gated: Scenario) -> None:
    loop = Loop(gated, BackgroundJobs())
    try:
        start_allocating(loop)
        # While the allocation waits at the gate, the cycles go on and the map lane
        # delivers new costmaps (a map update is due every half second, and at least 2 s
        # are stepped), and nobody has a goal yet. Whether the map itself changes depends
        # on when the mapper's jobs end on the wall clock: the robots stand still.
        waiting = [loop.step()]
        deadline = time.monotonic() + WAIT_S
        while len(waiting) < 20 or waiting[-1].costmap is waiting[0].costmap:
            assert time.monotonic() < deadline
            waiting.append(loop.step())
        assert waiting[0].costmap is not None
        assert all(goal is None for s in waiting for goal in s.goals_m)
        assert all("allocation" not in s.timings_s for s in waiting)
        GatedAllocator.gate.set()
        deadline = time.monotonic() + WAIT_S
        snapshot = loop.step()
        while snapshot.goals_m[0] is None and time.monotonic() < deadline:
            time.sleep(0.01)
            snapshot = loop.step()
        # Taken in the first cycle after the job ended, with the job's own duration:
        # each robot drives to the target the allocation gave it.
        assert snapshot.timings_s["allocation"] > 0.0
        assert len(GatedAllocator.targets_m) == len(snapshot.goals_m)
        for goal, target in zip(snapshot.goals_m, GatedAllocator.targets_m, strict=True):
            np.testing.assert_array_equal(goal, target)
    finally:
        GatedAllocator.gate.set()
        loop.server.close()


def test_a_failed_job_stops_the_run_in_the_next_cycle(gated: Scenario) -> None:
    GatedAllocator.error = ValueError("allocation broke")
    loop = Loop(gated, BackgroundJobs())
    try:
        start_allocating(loop)
        GatedAllocator.gate.set()
        deadline = time.monotonic() + WAIT_S
        with pytest.raises(ValueError, match="allocation broke"):
            while time.monotonic() < deadline:
                loop.step()
                time.sleep(0.01)
    finally:
        loop.server.close()


def test_slow_mapping_does_not_hold_back_the_control_loop_and_loses_no_scan(
    gated_map: Scenario,
) -> None:
    loop = Loop(gated_map, BackgroundJobs())
    try:
        deadline = time.monotonic() + WAIT_S
        while any(goal is None for goal in loop.step().goals_m):
            assert time.monotonic() < deadline
            time.sleep(0.01)
        GatedMapper.open_scans = GatedMapper.handed
        while not GatedMapper.waiting.is_set():
            assert time.monotonic() < deadline
            loop.step()
            GatedMapper.waiting.wait(0.01)
        # The mapper is stuck on a scan: SLAM and the local planner go on, the robots
        # drive on the last costmap, the map stays as it was.
        waiting = [loop.step() for _ in range(20)]
        assert waiting[-1].map.version == waiting[0].map.version
        moved_m = np.linalg.norm(waiting[-1].poses[:, :2] - waiting[0].poses[:, :2], axis=1)
        assert moved_m.max() > 0.05
        assert any(c.v != 0.0 for s in waiting for c in s.commands)
    finally:
        GatedMapper.gate.set()
        loop.server.close()
    # Closing waits for the queued jobs: every scan handed over is in the map.
    (mapper,) = GatedMapper.made
    assert len(mapper) == GatedMapper.handed > GatedMapper.open_scans


def test_a_lagging_map_lane_does_not_end_the_exploration(gated_map: Scenario) -> None:
    # The map lane takes the robots' first scans, then hangs: the frontiers the
    # decisions see stay those of the first, almost empty map, where nobody has a goal.
    GatedMapper.open_scans = 3
    loop = Loop(gated_map, BackgroundJobs())
    try:
        finish_after_s = gated_map.config.algorithms.server.finish_after_idle_s
        snapshots = [loop.step() for _ in range(round(3 * finish_after_s / 0.1))]
        assert GatedMapper.waiting.is_set()
        assert all(goal is None for goal in snapshots[-1].goals_m)
        assert snapshots[-1].explored_s is None and not snapshots[-1].finished
    finally:
        GatedMapper.gate.set()
        loop.server.close()


def test_loop_closures_are_matched_beside_the_control_loop(
    tiny_scenario: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    gate, started = threading.Event(), threading.Event()
    match_loop = LidarConstraints._match_loop

    def gated_match_loop(self, a, b, guess, limit_m):
        started.set()
        assert gate.wait(WAIT_S)
        return match_loop(self, a, b, guess, limit_m)

    monkeypatch.setattr(LidarConstraints, "_match_loop", gated_match_loop)
    loop = Loop(load_scenario(tiny_scenario), BackgroundJobs())
    localizer = loop.server._localizer
    try:
        deadline = time.monotonic() + WAIT_S
        while not started.is_set():
            assert time.monotonic() < deadline
            loop.step()
            started.wait(0.01)
        # The robots start side by side: their first keyframes are loop candidates. While
        # their matching waits, keyframes and iSAM2 updates go on without them. The robots
        # move once the decisions lane gives them goals, which takes wall time (a first
        # numba compile in a fresh environment), so the steps go on until then.
        robots = localizer.backend.robot_ids
        keyframes = sum(localizer.backend.keyframe_count(r) for r in robots)
        deadline = time.monotonic() + WAIT_S
        while sum(localizer.backend.keyframe_count(r) for r in robots) <= keyframes:
            assert time.monotonic() < deadline
            loop.step()
            time.sleep(0.01)
        assert localizer.scan_matcher.loops_added == 0
        gate.set()
        while localizer.scan_matcher.loops_added == 0:
            assert time.monotonic() < deadline
            loop.step()
            time.sleep(0.01)
    finally:
        gate.set()
        loop.server.close()
