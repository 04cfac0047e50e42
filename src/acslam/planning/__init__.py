"""Planning (thesis §4.7-4.8): global A* on the costmap and the local planners.

:mod:`~acslam.planning.astar` plans paths on plain arrays (cost, lethal mask, GridSpec);
:mod:`~acslam.planning.dwa` and :mod:`~acslam.planning.fgp` turn the lookahead point of
that path into velocity commands; :mod:`~acslam.planning.stuck` notices when a robot
makes no progress and :mod:`~acslam.planning.recovery` gets it going again. None of
them imports the simulator.
"""
