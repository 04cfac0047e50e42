"""Replays of real recordings (CARMEN laser logs, the UTIAS MRCLAM team) through the same
localizer stage as ``acslam run``, scored against what the recording provides.

:func:`localize` is the loop every replay shares: the recording plays as a
:class:`~acslam.sources.recorded.RecordedSource`, in the batches the server receives from
a live team, into :class:`~acslam.pipeline.perception.Perception`, which searches for
loop closures every map-update period as in the server. Presets of tuned algorithms for a
kind of recording are YAML files in ``presets/``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from acslam.config import AlgorithmsConfig, RobotsConfig, load_algorithms
from acslam.errors import ConfigError
from acslam.messages import LandmarkObservations, RobotMessage
from acslam.pipeline.perception import KeptScan, Perception
from acslam.pipeline.registry import LOCALIZERS
from acslam.pipeline.stages import AssociationResult, Localizer
from acslam.sources.recorded import RecordedSource


def preset(name: str) -> AlgorithmsConfig:
    """A built-in algorithms preset by name (``presets/<name>.yaml``)."""
    with resources.as_file(resources.files("acslam") / "replay" / "presets") as folder:
        path = Path(folder) / f"{name}.yaml"
        if not path.is_file():
            names = ", ".join(sorted(p.stem for p in Path(folder).glob("*.yaml")))
            raise ConfigError(name, "", f"no such algorithms preset; the built-in ones: {names}")
        return load_algorithms(path)


def algorithms_config(name_or_path: str | Path) -> AlgorithmsConfig:
    """A built-in preset by name, or an algorithms YAML file (a ``.yaml``/``.yml`` name,
    or any file that exists)."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return load_algorithms(path)
    return preset(str(name_or_path))


@dataclass(frozen=True)
class Replayed:
    """A replay's result: the localizer after the whole recording, every scan it kept and
    every landmark frame with what its points became, in the order they were played."""

    localizer: Localizer
    scans: list[KeptScan]
    landmarks: list[tuple[LandmarkObservations, list[AssociationResult]]]


def new_perception(
    algorithms: AlgorithmsConfig,
    starts: dict[int, np.ndarray],
    start_sigmas: dict[int, np.ndarray] | None = None,
) -> Perception:
    """The localizer stage ``algorithms`` names, fed as the server feeds it. The robot
    filter uses the default robot size (a recording does not say it); it only matters
    when a scan sees another robot of the team."""
    localizer = LOCALIZERS.create(
        algorithms.localizer,
        scan_matching=algorithms.scan_matching,
        starts=starts,
        **({} if start_sigmas is None else {"start_sigmas": start_sigmas}),
    )
    reach_m = RobotsConfig().radius_m + algorithms.server.robot_filter_margin_m
    return Perception(localizer, starts, reach_m, algorithms.server.map_update_period_s)


def localize(
    messages: Sequence[RobotMessage],
    algorithms: AlgorithmsConfig,
    starts: dict[int, np.ndarray],
    start_s: float | None = None,
    finish: bool = True,
) -> Replayed:
    """Play ``messages`` through the localizer stage ``algorithms`` names, from the
    recording's first stamp ``start_s`` (default: the first message's). With ``finish``
    the localizer ends the data with a last loop search and a settled estimate; without,
    the estimate is where a live server's would be when the run stopped.
    """
    perception = new_perception(algorithms, starts)
    localizer = perception.localizer
    source = RecordedSource(messages, algorithms.planning.control_period_s, start_s)
    scans: list[KeptScan] = []
    landmarks: list[tuple[LandmarkObservations, list[AssociationResult]]] = []
    while not source.finished:
        localized = perception.localize(source.receive(), source.time_s)
        scans += localized.scans
        landmarks += localized.landmarks
        source.advance()
    if finish:
        localizer.finish()
    return Replayed(localizer, scans, landmarks)
