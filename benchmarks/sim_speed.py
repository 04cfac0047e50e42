"""Simulator real-time factor against plain-NumPy ray casting.

The measuring code lives in ``acslam.benchmarks``; this prints the full-size figures of
its "simulator" group, the same rows as ``acslam bench`` (which runs every group).

Run: ``python benchmarks/sim_speed.py``
"""

from acslam.benchmarks import main_for

if __name__ == "__main__":
    main_for("simulator")
