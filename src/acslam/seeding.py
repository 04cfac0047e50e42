"""Named random streams derived from one scenario seed.

Each consumer draws from its own stream, keyed by what it is (the world, the landmarks,
robot i's odometry, ...), so adding a robot or a sensor leaves every other stream as it
was, and a run is reproducible from the scenario seed alone.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class Stream(IntEnum):
    WORLD = 0
    LANDMARKS = 1
    ODOMETRY = 2
    LIDAR = 3
    CAMERA = 4
    STARTS = 5


def rng(seed: int, stream: Stream, robot_id: int | None = None) -> np.random.Generator:
    """The generator of ``stream`` (for ``robot_id``, if per robot) under ``seed``."""
    key = (int(stream),) if robot_id is None else (int(stream), int(robot_id))
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=key))
