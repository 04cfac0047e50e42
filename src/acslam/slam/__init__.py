"""Centralized multi-robot factor-graph SLAM (thesis §4.4.1-4.4.2) on one iSAM2."""
