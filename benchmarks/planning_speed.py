"""Planning speed: our A* vs pyastar2d (or scipy), FGP solve time per team size.

The measuring code lives in ``acslam.benchmarks``; this prints the full-size figures of
its "planning" group, the same rows as ``acslam bench`` (which runs every group).

Run: ``python benchmarks/planning_speed.py``
"""

from acslam.benchmarks import main_for

if __name__ == "__main__":
    main_for("planning")
