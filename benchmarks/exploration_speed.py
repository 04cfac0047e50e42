"""Exploration speed: incremental EWFD vs the naive frontier scan, DBSCAN, allocation.

The measuring code lives in ``acslam.benchmarks``; this prints the full-size figures of
its "exploration" group, the same rows as ``acslam bench`` (which runs every group).

Run: ``python benchmarks/exploration_speed.py``
"""

from acslam.benchmarks import main_for

if __name__ == "__main__":
    main_for("exploration")
