"""Mapping speed: scan integration, move_scan and costmap on an 800 x 800 grid.

The measuring code lives in ``acslam.benchmarks``; this prints the full-size figures of
its "mapping" group, the same rows as ``acslam bench`` (which runs every group).

Run: ``python benchmarks/mapping_speed.py``
"""

from acslam.benchmarks import main_for

if __name__ == "__main__":
    main_for("mapping")
