"""Centralized multi-robot factor-graph SLAM (thesis §4.4.1-4.4.2) on one iSAM2."""

from acslam.slam.backend import AssociationResult, SlamBackend

__all__ = ["AssociationResult", "SlamBackend"]
