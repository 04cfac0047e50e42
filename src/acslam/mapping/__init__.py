"""Mapping (thesis §4.4.3): log-odds occupancy grids from posed scans, and costmaps."""
