"""Parameters of the global and local planner plugins, apart from their code.

Validating a scenario needs only these models, so it imports no algorithm (and none of
GTSAM, numba or SciPy): each model is declared to its registry with the implementation,
which is imported when the plugin is first built.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from acslam.config import NonNegativeFloat, PositiveFloat, StageParams
from acslam.pipeline.registry import GLOBAL_PLANNERS, LOCAL_PLANNERS


@GLOBAL_PLANNERS.declare("acslam.planning.astar:AstarPlanner")
class AstarParams(StageParams):
    """The A* global planner (thesis §4.7)."""

    name: Literal["astar"] = "astar"
    # A* step cost = step length (m) * (1 + cost_weight * cell cost).
    cost_weight: NonNegativeFloat = 5.0
    # Start/goal inside lethal cells snap to the nearest free cell within this radius:
    # a robot localised a few cells into the inflation band must still get a path.
    max_snap_m: NonNegativeFloat = 0.5
    # Line-of-sight smoothing of the A* path (shorter in metres; cost no longer optimal).
    shortcut: bool = True


@LOCAL_PLANNERS.declare("acslam.planning.dwa:DynamicWindowPlanner")
class DwaParams(StageParams):
    """DWA (eqs. 4.48-4.56): velocity samples and the weights of eq. 4.51."""

    name: Literal["dwa"] = "dwa"
    v_samples: Annotated[int, Field(ge=2)] = 11
    omega_samples: Annotated[int, Field(ge=3)] = 21
    weight_progress: NonNegativeFloat = 1.0
    weight_heading: NonNegativeFloat = 0.3
    weight_costmap: NonNegativeFloat = 0.5
    weight_robot: NonNegativeFloat = 0.5
    # Each arc is sampled at least this often over T_p (and every half cell).
    min_rollout_steps: Annotated[int, Field(ge=2)] = 10


@LOCAL_PLANNERS.declare("acslam.planning.fgp:FactorGraphPlanner")
class FgpParams(StageParams):
    """The joint factor-graph planner (eqs. 4.59-4.71).

    Sigmas: start position is the measured pose (tight); start velocity may change by
    about one acceleration step; dynamics position sigma keeps the states kinematically
    consistent, the velocity sigma is ~max_acc * dt.
    """

    name: Literal["fgp"] = "fgp"
    horizon_steps: Annotated[int, Field(ge=2)] = 10  # N, dt = T_p / N = 0.2 s
    start_sigma_m: PositiveFloat = 0.001
    start_sigma_mps: PositiveFloat = 0.05
    dynamics_sigma_m: PositiveFloat = 0.005
    dynamics_sigma_mps: PositiveFloat = 0.1
    goal_sigma_m: PositiveFloat = 0.2  # moderate: the goal may yield to obstacles
    obstacle_sigma: PositiveFloat = 0.1  # unitless error 1 - d / d_max
    robot_sigma: PositiveFloat = 0.05  # unitless error 1 - d / d_max
    # Cap on Levenberg-Marquardt linear solves per cycle (accepted and rejected steps).
    max_iterations: Annotated[int, Field(ge=1)] = 20
    # Sideways nudge of the initial guess when another robot is dead ahead: a symmetric
    # head-on meeting is a saddle of eq. 4.69 where both robots would stop; both keep right.
    keep_right_m: NonNegativeFloat = 0.1
