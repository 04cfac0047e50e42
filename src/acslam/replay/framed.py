"""A team's recording replayed without its start poses: one frame per robot, merged when
the robots' sightings of each other place one frame in another.

Each robot starts at the origin of its own frame with a localizer of its own (its own
graph and landmarks). A sighting between robots of two frames (the seen robot named by a
marker of its own, as MRCLAM's barcodes) is evidence, not a factor: it puts the seen
robot at one place in each frame (:mod:`acslam.slam.frame_alignment`). Every
``MERGE_CHECK_PERIOD_S`` each pair of frames with sightings between them is fitted from
all of them, at the poses the frames' current estimates give the robots at each
sighting's stamp. An accepted fit merges the two frames into the frame of the lower robot
id: a new localizer starts the other frame's robots at their starts carried through the
fit (held as loosely as the fit is known, and no tighter than ``MERGED_START_SIGMAS``),
and every message the merged robots sent so far is replayed into it, the sightings
between them now as factors. So the merged frame holds what one graph with those starts
would have made, and later sightings keep refining where the frames lie.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from acslam.config import AlgorithmsConfig
from acslam.geometry import between_rows, compose, compose_rows
from acslam.messages import LandmarkObservations, OdometryIncrement, RobotMessage, RobotSighting
from acslam.pipeline.frames import MERGED_START_SIGMAS
from acslam.pipeline.perception import Perception
from acslam.pipeline.stages import AssociationResult
from acslam.replay import new_perception
from acslam.schedule import Periodic
from acslam.slam.frame_alignment import AlignmentParams, FrameAlignment, align_frames
from acslam.sources.recorded import RecordedSource

MERGE_CHECK_PERIOD_S = 5.0
"""Frames are fitted this often (recording time): each fit places every sighting so far
again, at the frames' current estimates, and sightings come a few per second."""


class _OdometryTrack:
    """A robot's odometry integrated from its frame's origin, to place a sighting between
    two keyframes: the pose at a stamp is the keyframe before it, as the graph now has it,
    with the odometry since that keyframe."""

    def __init__(self) -> None:
        self._stamps = np.zeros(1024)
        self._poses = np.zeros((1024, 3))
        self._count = 0

    def add(self, message: OdometryIncrement) -> None:
        if self._count == 0:
            self._append(message.start_stamp, np.zeros(3))
        if message.stamp > self._stamps[self._count - 1]:
            delta = np.array([message.dx, message.dy, message.dtheta])
            self._append(message.stamp, compose(self._poses[self._count - 1], delta))

    def _append(self, stamp: float, pose: np.ndarray) -> None:
        if self._count == len(self._stamps):
            self._stamps = np.concatenate([self._stamps, np.zeros(self._count)])
            self._poses = np.vstack([self._poses, np.zeros((self._count, 3))])
        self._stamps[self._count], self._poses[self._count] = stamp, pose
        self._count += 1

    def at(self, stamps: np.ndarray) -> np.ndarray:
        """(N, 3) integrated poses at the last odometry stamp at or before each stamp."""
        index = np.searchsorted(self._stamps[: self._count], stamps, side="right") - 1
        return self._poses[np.clip(index, 0, max(self._count - 1, 0))]


@dataclass
class Frame:
    """Robots localized together: the frame of robot ``base``, their starts in it (and
    sigmas of those a merge placed), and every landmark frame with what its points became."""

    base: int
    starts: dict[int, np.ndarray]
    start_sigmas: dict[int, np.ndarray]
    perception: Perception
    landmarks: list[tuple[LandmarkObservations, list[AssociationResult]]] = field(
        default_factory=list
    )

    def poses_at(self, robot_id: int, stamps: np.ndarray, odometry: _OdometryTrack) -> np.ndarray:
        """(N, 3) poses of the robot at ``stamps`` in this frame (see :class:`_OdometryTrack`)."""
        keyframe_stamps, keyframe_poses = self.perception.localizer.trajectory(robot_id)
        index = np.clip(np.searchsorted(keyframe_stamps, stamps, side="right") - 1, 0, None)
        since = between_rows(odometry.at(keyframe_stamps[index]), odometry.at(stamps))
        return compose_rows(keyframe_poses[index], since)


def frame_of(frames: Iterable[Frame], robot_id: int) -> Frame:
    for frame in frames:
        if robot_id in frame.starts:
            return frame
    raise ValueError(f"a message of robot {robot_id}, which is not in the team")


@dataclass(frozen=True)
class FrameContents:
    """A frame's robots' keyframe trajectories ((N, 3) each) and its landmarks, in its
    coordinates: what a figure of a merge shows."""

    tracks: dict[int, np.ndarray]
    landmarks: np.ndarray

    @classmethod
    def of(cls, frame: Frame) -> FrameContents:
        localizer = frame.perception.localizer
        tracks = {r: localizer.trajectory(r)[1] for r in sorted(frame.starts)}
        return cls(tracks, localizer.landmarks())


@dataclass(frozen=True)
class Merge:
    """Frame ``merged`` (its robots ``robot_ids``) placed in frame ``into`` at ``stamp``
    by ``alignment``; the merged frame's graph, once every message so far was replayed
    into it, put the merged frame's origin at ``origin_in_into`` and the latest keyframe
    of every robot of both frames at ``placed`` (stamp, pose). ``before`` holds both
    frames as they were, ``after`` the merged one."""

    stamp: float
    into: int
    merged: int
    robot_ids: list[int]
    alignment: FrameAlignment
    origin_in_into: np.ndarray
    placed: dict[int, tuple[float, np.ndarray]]
    before: tuple[FrameContents, FrameContents]
    after: FrameContents


@dataclass
class FramedReplay:
    """The frames at the end of a replay (by base robot), the merges in order, and the
    recording's first step time."""

    frames: dict[int, Frame]
    merges: list[Merge]
    start_s: float


class _Team:
    """The frames while the recording plays."""

    def __init__(
        self,
        algorithms: AlgorithmsConfig,
        robot_ids: Sequence[int],
        params: AlignmentParams,
        start_s: float,
    ) -> None:
        """``start_s``: the recording's first step time (a merge replays from it)."""
        self.algorithms = algorithms
        self.params = params
        self.frames = {r: self._new_frame(r, {r: np.zeros(3)}, {}) for r in robot_ids}
        self.odometry = {r: _OdometryTrack() for r in robot_ids}
        self.history: list[RobotMessage] = []
        self.evidence: list[RobotSighting] = []
        self.merges: list[Merge] = []
        self.start_s = start_s

    def _new_frame(
        self, base: int, starts: dict[int, np.ndarray], sigmas: dict[int, np.ndarray]
    ) -> Frame:
        return Frame(base, starts, sigmas, new_perception(self.algorithms, starts, sigmas or None))

    def play(self, messages: list[RobotMessage], now_s: float) -> None:
        """One batch: each frame gets its robots' messages; sightings across frames are
        kept as evidence."""
        self.history += messages
        batches: dict[int, list[RobotMessage]] = {base: [] for base in self.frames}
        for message in messages:
            if isinstance(message, OdometryIncrement):
                self.odometry[message.robot_id].add(message)
            frame = frame_of(self.frames.values(), message.robot_id)
            if (
                isinstance(message, RobotSighting)
                and message.observed_id not in frame.starts
                and message.observed_id in self.odometry
            ):
                self.evidence.append(message)
                continue
            batches[frame.base].append(message)
        for base, frame in self.frames.items():
            frame.landmarks += frame.perception.localize(batches[base], now_s).landmarks

    def pairs(self, a: Frame, b: Frame) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) places of the seen robots of the sightings between frames ``a`` and
        ``b``, in each frame."""
        robots = {*a.starts, *b.starts}
        sightings = [s for s in self.evidence if s.robot_id in robots and s.observed_id in robots]
        stamps = np.array([s.stamp for s in sightings])
        observers = np.array([s.robot_id for s in sightings])
        seen = np.array([s.observed_id for s in sightings])
        points = np.array([[*s.point[:2], 0.0] for s in sightings]).reshape(-1, 3)
        by_observer, by_seen = np.zeros((len(sightings), 2)), np.zeros((len(sightings), 2))
        for robot_id in robots:
            poses = frame_of((a, b), robot_id).poses_at(robot_id, stamps, self.odometry[robot_id])
            observing, observed = observers == robot_id, seen == robot_id
            by_observer[observing] = compose_rows(poses[observing], points[observing])[:, :2]
            by_seen[observed] = poses[observed, :2]
        observer_in_a = np.array([r in a.starts for r in observers], dtype=bool)[:, None]
        in_a = np.where(observer_in_a, by_observer, by_seen)
        in_b = np.where(observer_in_a, by_seen, by_observer)
        return in_a, in_b

    def try_merges(self, now_s: float) -> None:
        """Fit every pair of frames; merge the first accepted, then fit again."""
        merged = True
        while merged:
            merged = False
            bases = sorted(self.frames)
            for i, base_a in enumerate(bases):
                for base_b in bases[i + 1 :]:
                    a, b = self.frames[base_a], self.frames[base_b]
                    points_a, points_b = self.pairs(a, b)
                    if len(points_a) < self.params.min_inliers:
                        continue
                    alignment = align_frames(points_a, points_b, self.params)
                    if alignment.accepted:
                        self._merge(a, b, alignment, now_s)
                        merged = True
                        break
                if merged:
                    break

    def _merge(self, a: Frame, b: Frame, alignment: FrameAlignment, now_s: float) -> None:
        """One frame for both, in ``a``'s, with every message of theirs replayed."""
        assert alignment.pose_b_in_a is not None
        starts = dict(a.starts)
        sigmas = dict(a.start_sigmas)
        for robot_id, start in b.starts.items():
            starts[robot_id] = compose(alignment.pose_b_in_a, start)
            earlier = b.start_sigmas.get(robot_id, np.zeros(3))
            sigmas[robot_id] = np.maximum(np.hypot(alignment.sigmas, earlier), MERGED_START_SIGMAS)
        frame = self._new_frame(a.base, starts, sigmas)
        robots = set(starts)
        own = [
            m for m in self.history
            if m.robot_id in robots
            and (not isinstance(m, RobotSighting) or m.observed_id in robots)
        ]  # fmt: skip
        source = RecordedSource(own, self.algorithms.planning.control_period_s, self.start_s)
        while not source.finished:
            frame.landmarks += frame.perception.localize(source.receive(), source.time_s).landmarks
            source.advance()
        self.evidence = [
            s for s in self.evidence if not (s.robot_id in robots and s.observed_id in robots)
        ]
        del self.frames[b.base]
        self.frames[a.base] = frame
        localizer = frame.perception.localizer
        after = FrameContents.of(frame)
        self.merges.append(
            Merge(
                now_s, a.base, b.base, sorted(b.starts), alignment,
                after.tracks[b.base][0],
                {r: _latest_keyframe(*localizer.trajectory(r)) for r in sorted(robots)},
                (FrameContents.of(a), FrameContents.of(b)),
                after,
            )
        )  # fmt: skip


def _latest_keyframe(stamps: np.ndarray, poses: np.ndarray) -> tuple[float, np.ndarray]:
    return float(stamps[-1]), poses[-1]


def localize_in_frames(
    messages: Sequence[RobotMessage],
    algorithms: AlgorithmsConfig,
    robot_ids: Sequence[int],
    params: AlignmentParams | None = None,
    finish: bool = True,
) -> FramedReplay:
    """Play ``messages`` with each robot of ``robot_ids`` in its own frame, merging frames
    as the module docstring says; ``finish`` as for :func:`acslam.replay.localize`."""
    source = RecordedSource(messages, algorithms.planning.control_period_s)
    team = _Team(algorithms, robot_ids, params or AlignmentParams(), source.time_s)
    checks = Periodic(MERGE_CHECK_PERIOD_S)
    while not source.finished:
        team.play(source.receive(), source.time_s)
        if len(team.frames) > 1 and checks.due(source.time_s):
            team.try_merges(source.time_s)
        source.advance()
    if finish:
        for frame in team.frames.values():
            frame.perception.localizer.finish()
    return FramedReplay(team.frames, team.merges, team.start_s)
