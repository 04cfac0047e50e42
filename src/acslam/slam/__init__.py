"""Centralized multi-robot factor-graph SLAM (thesis §4.4.1-4.4.2) on one iSAM2."""

from acslam.slam.backend import SlamBackend

__all__ = ["SlamBackend"]
