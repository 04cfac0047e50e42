"""Pose geometry against hand-worked answers."""

from __future__ import annotations

import math

import numpy as np

from acslam.geometry import beam_ends


def test_beams_end_where_their_range_reaches_from_the_turned_sensor() -> None:
    pose = np.array([1.0, -2.0, math.pi / 2])  # facing +y
    ends = beam_ends(pose, np.array([0.0, math.pi / 2, math.pi]), np.array([2.0, 1.0, 0.5]))
    np.testing.assert_allclose(ends, [[1.0, 0.0], [0.0, -2.0], [1.0, -2.5]], atol=1e-12)
    # No return: the beam runs on for ever along its heading.
    (far,) = beam_ends(pose, np.array([0.0]), np.array([np.inf]))
    assert far[1] == np.inf
