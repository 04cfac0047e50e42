"""Scan matching speed: point-to-line ICP of two simulated 360-beam scans.

The measuring code lives in ``acslam.benchmarks``; this prints the full-size figures of
its "scan matching" group, the same rows as ``acslam bench`` (which runs every group).

Run: ``python benchmarks/scan_matching_speed.py``
"""

from acslam.benchmarks import main_for

if __name__ == "__main__":
    main_for("scan matching")
