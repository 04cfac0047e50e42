"""The localizer plugin's parameters (:class:`~acslam.config.SlamConfig`) declared to its
registry, apart from its code: validating a scenario imports no GTSAM."""

from __future__ import annotations

from acslam.config import SlamConfig
from acslam.pipeline.registry import LOCALIZERS

LOCALIZERS.declare("acslam.slam.localizer:Isam2Localizer")(SlamConfig)
