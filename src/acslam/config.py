"""Scenario configuration: schema, defaults, loading and validation.

A scenario is a YAML file, or a built-in by name (``acslam scenarios`` lists them). Every
field has a default, so a scenario only states what differs. The thesis names the
parameters of its algorithms but gives no values; where a default below is ours, the
comment says where it comes from (robot and sensor numbers are the TurtleBot3 / LDS-02
data sheet figures of thesis §5.1).

Errors are raised as :class:`~acslam.errors.ConfigError` naming the file and the field
path, e.g. ``scenario.yaml: robots.starts[1]: start pose lies in an obstacle``.
"""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializeAsAny,
    ValidationError,
    WrapValidator,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError

from acslam.errors import ConfigError
from acslam.files import parse_yaml, read_text, read_yaml
from acslam.text import plural

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegativeFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Probability = Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]
Pose = tuple[FiniteFloat, FiniteFloat, FiniteFloat]


def ordered(*pairs: tuple[str, str, bool]) -> Any:
    """A model validator: each ``(low, high, strict)`` field pair must satisfy low < high
    (strict) or low <= high."""

    def check(model: BaseModel) -> BaseModel:
        for low, high, strict in pairs:
            a, b = getattr(model, low), getattr(model, high)
            if a > b or (strict and a == b):
                raise ValueError(f"{low} must {'be below' if strict else 'not exceed'} {high}")
        return model

    return model_validator(mode="after")(check)


class Section(BaseModel):
    """Base of every config section: unknown keys are errors, values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True)


class StageParams(Section):
    """Base of a pipeline stage's parameters: ``name`` picks the plugin
    (:mod:`acslam.pipeline.registry`), the other fields are that plugin's own."""

    name: str


# --------------------------------------------------------------------------- worlds


class ThesisWorld(Section):
    """One of the lab environments of thesis §5.2, approximated on a 40 m x 40 m grid."""

    generator: Literal["thesis"]
    experiment: Annotated[int, Field(ge=1, le=5)]
    resolution_m: PositiveFloat = 0.05


class VineyardWorld(Section):
    """Parallel vine rows of plants with random gaps, headlands at both ends, a fence."""

    generator: Literal["vineyard"]
    resolution_m: PositiveFloat = 0.05
    row_count: Annotated[int, Field(ge=1)] = 6
    row_length_m: PositiveFloat = 14.0
    row_spacing_m: PositiveFloat = 2.5
    # Touching canopies: a row is a wall but for the gaps a missing plant leaves.
    plant_spacing_m: PositiveFloat = 0.5
    plant_radius_m: PositiveFloat = 0.2
    gap_probability: Probability = 0.1
    headland_m: PositiveFloat = 3.0
    jitter_m: NonNegativeFloat = 0.05


class DungeonWorld(Section):
    """Rectangular rooms joined by corridors through doors, inside an outer wall."""

    generator: Literal["dungeon"]
    resolution_m: PositiveFloat = 0.05
    width_m: PositiveFloat = 20.0
    height_m: PositiveFloat = 20.0
    room_count: Annotated[int, Field(ge=1)] = 8
    room_size_min_m: PositiveFloat = 3.0
    room_size_max_m: PositiveFloat = 6.0
    corridor_width_m: PositiveFloat = 1.2
    door_width_m: PositiveFloat = 0.9
    wall_thickness_m: PositiveFloat = 0.15

    _sizes = ordered(("room_size_min_m", "room_size_max_m", False))


class OsmWorld(Section):
    """Roads of an OpenStreetMap file (.osm, .osm.pbf, .osm.bz2) as free space."""

    generator: Literal["osm"]
    file: Path
    resolution_m: PositiveFloat = 0.25
    center_lat_lon: tuple[FiniteFloat, FiniteFloat] | None = None
    width_m: PositiveFloat = 200.0
    height_m: PositiveFloat = 200.0
    road_width_m: PositiveFloat = 4.0
    highway_types: list[str] | None = None


class FloorplanWorld(Section):
    """A floor-plan image: grey >= free_threshold is free, the rest occupied."""

    generator: Literal["floorplan"]
    file: Path
    resolution_m: PositiveFloat = 0.05
    free_threshold: Annotated[int, Field(ge=1, le=255)] = 250


class MapFileWorld(Section):
    """A ROS map_server map (yaml + image); unknown cells count as occupied."""

    generator: Literal["map_file"]
    file: Path


_WORLD_TAGS = ("thesis", "vineyard", "dungeon", "osm", "floorplan", "map_file")
WorldConfig = Annotated[
    ThesisWorld | VineyardWorld | DungeonWorld | OsmWorld | FloorplanWorld | MapFileWorld,
    Field(discriminator="generator"),
]


class LandmarkConfig(Section):
    """Camera landmarks placed at world creation, in free space close to structure."""

    density_per_m2: NonNegativeFloat = 0.5
    max_obstacle_distance_m: PositiveFloat = 0.3
    z_min_m: FiniteFloat = 0.1
    z_max_m: FiniteFloat = 1.0

    _heights = ordered(("z_min_m", "z_max_m", False))


# --------------------------------------------------------------------------- robots


class RobotsConfig(Section):
    """The team: start poses ``[x, y, theta]`` and the TurtleBot3 Burger's limits.

    ``starts``: a list of poses; ``random``, a seeded draw spread over the world, each
    start at least ``min_start_separation_m`` from the others and out of their sight
    (:mod:`acslam.worlds.starts`); or none, the world's suggested starts.
    ``relative_starts``: ``known``, the server is given the starts; ``unknown``, each
    robot starts at the origin of its own frame and the server merges the frames from
    the data (:mod:`acslam.pipeline.frames`; the starts then only place the simulated
    robots).
    """

    count: Annotated[int, Field(ge=1)] | None = None
    starts: list[Pose] | Literal["random"] | None = None
    relative_starts: Literal["known", "unknown"] = "known"
    min_start_separation_m: PositiveFloat = 3.0
    radius_m: PositiveFloat = 0.105
    max_v_mps: PositiveFloat = 0.22
    max_omega_radps: PositiveFloat = 2.84
    max_acc_v_mps2: PositiveFloat = 0.5
    max_acc_omega_radps2: PositiveFloat = 3.0

    @field_validator("starts", mode="before")
    @classmethod
    def _starts_word(cls, value: Any) -> Any:
        """One clear error for a word other than ``random``, not one per union member."""
        if isinstance(value, str) and value != "random":
            raise ValueError(f"{value!r}: give a list of [x, y, theta] poses or 'random'")
        return value

    def team_size(self) -> int:
        """``count``, else one robot per listed start, else one."""
        if self.count is not None:
            return self.count
        return len(self.starts) if isinstance(self.starts, list) and self.starts else 1


# --------------------------------------------------------------------------- sensors


class OdometryConfig(Section):
    """Odometry/IMU estimate (thesis eqs. 4.73-4.75).

    Biases follow the first-order Gauss-Markov process b_t = a b_{t-1} + N(0, s^2) of
    eq. 4.73, stated in continuous time so it does not depend on the step: a =
    exp(-dt / correlation_time_s) and s = bias_std * sqrt(1 - a^2), which keeps the
    stationary standard deviation at ``bias_std``. Scale errors (4.74-4.75) are drawn
    once per robot from N(0, scale_std^2).
    """

    rate_hz: PositiveFloat = 20.0
    bias_v_std_mps: NonNegativeFloat = 0.005
    bias_omega_std_radps: NonNegativeFloat = 0.002
    bias_correlation_time_s: PositiveFloat = 30.0
    scale_v_std: NonNegativeFloat = 0.02
    scale_omega_std: NonNegativeFloat = 0.02


class LidarConfig(Section):
    """2D LiDAR like the LDS-02: 360 beams over 360 deg, 8 m, 10 Hz.

    Range noise std is ``range_noise_std_m + range_noise_rel * range``, a fit of the
    data sheet's +-10 mm below 0.3 m and +-3 % (taken as 2 sigma) beyond.
    """

    rate_hz: PositiveFloat = 10.0
    beams: Annotated[int, Field(ge=1)] = 360
    fov_rad: Annotated[float, Field(gt=0, le=2 * math.pi)] = 2 * math.pi
    range_min_m: NonNegativeFloat = 0.16
    range_max_m: PositiveFloat = 8.0
    range_noise_std_m: NonNegativeFloat = 0.005
    range_noise_rel: NonNegativeFloat = 0.015
    angle_noise_std_rad: NonNegativeFloat = 0.002

    _ranges = ordered(("range_min_m", "range_max_m", True))


class CameraConfig(Section):
    """Landmark camera (RGB-D, OAK-D Pro-like): range, horizontal FOV, point noise."""

    rate_hz: PositiveFloat = 5.0
    range_min_m: NonNegativeFloat = 0.3
    range_max_m: PositiveFloat = 4.0
    fov_rad: Annotated[float, Field(gt=0, le=2 * math.pi)] = math.radians(70.0)
    noise_std_m: NonNegativeFloat = 0.03

    _ranges = ordered(("range_min_m", "range_max_m", True))


class SensorsConfig(Section):
    odometry: OdometryConfig = OdometryConfig()
    lidar: LidarConfig = LidarConfig()
    camera: CameraConfig = CameraConfig()


class SimConfig(Section):
    """Simulator clock: the fixed integration step of eq. 4.72 and the time limit; and the
    largest world grid a run may allocate (checked before it does, see
    :mod:`acslam.worlds.limits`).

    ``dt_s`` may not exceed the control period or any sensor period: a step longer than a
    period would fire that sensor (or the planner) less often than its rate says. The
    default cell budget, 64 M cells, holds a 400 m x 400 m world at 0.05 m (a 200 m x 200 m
    one at 0.025 m) and keeps a run within a workstation's memory.
    """

    dt_s: PositiveFloat = 0.02
    max_time_s: PositiveFloat = 600.0
    max_grid_cells: Annotated[int, Field(ge=1)] = 64_000_000


# --------------------------------------------------------------------------- algorithms


class SlamConfig(StageParams):
    """Factor-graph SLAM (thesis §4.4.1-4.4.2): the ``isam2`` localizer. Noise sigmas are ours.

    Odometry sigmas grow with the distance / angle travelled between keyframes, never
    below the ``*_min_*`` floors. ``huber_k`` is the Huber threshold on the
    whitened (Mahalanobis) residual norm of an observation factor; 2.8 is the 95 %
    quantile of a 3-dof chi distribution, so inliers keep their full Gaussian weight.
    The association gates: a Euclidean pre-gate (``association_gate_m``, widened for a
    point whose own covariance, pose marginal included, reaches further, so a robot that
    drifted can still find its landmarks), then the squared Mahalanobis gate (11.34 =
    chi-square 3 dof, 99 %). ``association_min_likelihood`` is PDA's clutter term: the
    density (1/m^3) of a point from no mapped landmark (one not mapped yet, or a false
    detection), which competes with the candidates' Gaussian densities, so a lone
    candidate under a wide covariance is not taken for certain (0.05: the simulated worlds'
    0.5 landmarks per m^2 over 0.9 m of height, about a tenth of them not yet mapped where
    a robot looks; see :func:`~acslam.slam.association.exclusive_probabilities`). A point
    with no candidate starts a new landmark only if every landmark is further than
    ``new_landmark_mahalanobis_gate`` (squared; 25 ~ 5 sigma): in between it is ambiguous
    and dropped, otherwise the 1 % of true re-observations outside the 99 % gate would
    each spawn a duplicate landmark. The points of one frame are associated jointly (one
    landmark takes at most one point); a point is used only if its assigned landmark has
    PDA probability >= ``association_min_best_probability`` among the candidates no other
    point took (else dropped as ambiguous), and soft factors go to candidates with
    probability >= ``association_min_probability``. A new landmark is first tentative: it
    enters the graph once seen in ``landmark_confirmations`` frames by the same robot, the
    last within ``tentative_timeout_s`` of the previous; otherwise it is forgotten.
    iSAM2 checks for relinearization every
    ``isam_relinearize_skip`` updates, of variables whose update exceeds
    ``isam_relinearize_threshold`` (GTSAM's defaults are 10 and 0.1). Every update: with
    10, the pose the robots drive by lagged the final estimate by up to 0.46 m on the IPA
    lab plan (Huber weights and headings stay at a linearization point up to a second old
    while loop closures arrive), and the final RMSE there was 0.281 m against 0.065 m, at
    no more SLAM time. A threshold of 0.01 instead cost 5-10x the update time and was
    less accurate on office_b.
    ``isam_factorization``: Cholesky is iSAM2's fast default; QR is slower but does not
    square the condition number, which long laser-only graphs (millimetre scan-match
    sigmas beside metres of drift, e.g. the fr079 log) need to avoid an "indeterminate
    linear system".
    ``prior_sigma_*``: how well the known start poses are known (thesis eq. 4.9 asks for
    a small Sigma_0 and gives none). Every other factor is relative, so these priors alone
    fix the map's place and heading: three robots started 0.6 m apart under 0.01 m and
    0.01 rad leave the heading about 5 mrad free (1 sigma), 0.25 m at the far end of a
    50 m building (office_b seed 0: the whole map turned by 6.8 mrad, worst RMSE 0.188 m;
    at 1 mm and 1 mrad, 1.3 mrad and 0.044 m). The simulator's start poses are exact, so
    the defaults are 1 mm and 1 mrad; widen them to what placing
    real robots achieves.
    """

    name: Literal["isam2"] = "isam2"
    prior_sigma_xy_m: PositiveFloat = 0.001
    prior_sigma_theta_rad: PositiveFloat = 0.001
    odom_sigma_xy_per_m: PositiveFloat = 0.05
    odom_sigma_theta_per_rad: PositiveFloat = 0.05
    odom_sigma_theta_per_m: NonNegativeFloat = 0.02
    odom_sigma_min_xy_m: PositiveFloat = 0.005
    odom_sigma_min_theta_rad: PositiveFloat = 0.005
    # The default simulated camera's point noise (CameraConfig.noise_std_m); the thesis
    # leaves Sigma_lm open. A larger sigma only throws information away: at 0.1 m the
    # landmark factors carried a tenth of what the camera measures.
    landmark_sigma_m: PositiveFloat = 0.03
    # Along the line of sight a camera's range error often grows with the range (depth
    # from disparity or from a marker's apparent size): the radial sigma is
    # hypot(landmark_radial_sigma_m, landmark_radial_sigma_per_m x range).
    landmark_radial_sigma_m: NonNegativeFloat = 0.0
    landmark_radial_sigma_per_m: NonNegativeFloat = 0.0
    landmark_angular_sigma_rad: NonNegativeFloat = 0.0
    huber_k: PositiveFloat = 2.8
    keyframe_distance_m: PositiveFloat = 0.3
    keyframe_angle_rad: PositiveFloat = 0.3
    # Where a robot drives through space its team already keyframed (a keyframe within
    # mapped_space_radius_m: another robot's, or its own from mapped_space_min_path_m or
    # more back along its path), it opens a keyframe only every mapped_keyframe_distance_m
    # of path (turns still open one every keyframe_angle_rad): the graph grows with the
    # mapped area, not with every pass (acslam.slam.keyframe_coverage). At most
    # keyframe_distance_m: off.
    mapped_keyframe_distance_m: NonNegativeFloat = 1.5
    mapped_space_radius_m: PositiveFloat = 0.5
    mapped_space_min_path_m: PositiveFloat = 5.0
    association_gate_m: PositiveFloat = 1.0
    association_mahalanobis_gate: PositiveFloat = 11.34
    association_min_likelihood: NonNegativeFloat = 0.05
    new_landmark_mahalanobis_gate: PositiveFloat = 25.0
    association_min_best_probability: Probability = 0.9
    association_min_probability: Probability = 0.05
    landmark_confirmations: Annotated[int, Field(ge=1)] = 3
    tentative_timeout_s: PositiveFloat = 10.0
    # A landmark's covariance relative to a robot's keyframe, from one iSAM2 joint
    # marginal, serves that robot's frames for this many keyframes after it, with the
    # odometry chain since added; so does the robot's own pose marginal (0: fresh
    # marginals in every frame).
    association_covariance_reuse_keyframes: Annotated[int, Field(ge=0)] = 5
    # A landmark that got a factor within this many iSAM2 updates enters that joint
    # marginal; an older one sits deep in the Bayes tree, where a marginal costs more the
    # longer the trajectory, and is scored with the last marginal computed for it (a
    # marginal only shrinks as the graph learns) and no pose-landmark cross term.
    association_joint_marginal_max_age_updates: Annotated[int, Field(ge=0)] = 10
    # A point and a landmark that both carry binary descriptors (ORB: 256 bits) are
    # candidates only within this Hamming distance; ORB-SLAM matches within 50-100 bits.
    association_max_descriptor_bits: Annotated[int, Field(ge=0)] = 64
    # ... and only within this many bits of the closest candidate's descriptor (matched
    # ORB points of the TUM fr1/xyz desk differ by 11-37 bits, 10th-90th percentile).
    association_descriptor_margin_bits: Annotated[int, Field(ge=0)] = 10
    isam_relinearize_threshold: PositiveFloat = 0.05
    isam_relinearize_skip: Annotated[int, Field(ge=1)] = 1
    isam_factorization: Literal["CHOLESKY", "QR"] = "CHOLESKY"
    # A keyframe this far from where it was last reported moved is reported again (the
    # map re-places its scans): half a 5 cm cell, so the map never lags by more.
    correction_threshold_m: PositiveFloat = 0.025
    # Online odometry calibration (acslam.slam.odometry_calibration): each robot's travel
    # and turn scale errors and travel bias, learned from its sequential scan matches and
    # taken out of its odometry. The prior, the travel bias's level and random walk, and
    # the turn-rate bias counted as noise default to the simulated robot's odometry
    # (OdometryConfig: 2 % scale errors, biases of 0.005 m/s and 0.002 rad/s wandering
    # over ~30 s); for another robot state its own.
    odometry_calibration: bool = True
    calibration_scale_prior_std: PositiveFloat = 0.05
    calibration_travel_bias_std_mps: PositiveFloat = 0.005
    calibration_travel_bias_walk_mps_per_sqrt_s: NonNegativeFloat = 0.001
    calibration_turn_bias_std_radps: NonNegativeFloat = 0.002
    # Squared normalised innovation above which a match is not used (chi-square, 2 dof,
    # 99.9 %).
    calibration_gate: PositiveFloat = 13.8


class MappingConfig(StageParams):
    """Log-odds occupancy grid (thesis §4.4.3, eqs. 4.25-4.34): the ``log-odds`` mapper."""

    name: Literal["log-odds"] = "log-odds"

    resolution_m: PositiveFloat = 0.05
    delta_free: Annotated[float, Field(lt=0, allow_inf_nan=False)] = -0.4
    delta_occ: PositiveFloat = 0.85
    distance_alpha_per_m: NonNegativeFloat = 0.05
    # Half a cell: with sigma = one cell the kernel's +0.52 at the neighbour in front of a
    # wall outweighs that cell's free update and every wall grows a cell toward the robot.
    hit_sigma_m: PositiveFloat = 0.025
    hit_radius_m: NonNegativeFloat = 0.1
    log_odds_min: FiniteFloat = -5.0
    log_odds_max: FiniteFloat = 5.0
    occupied_probability: Probability = 0.65
    free_probability: Probability = 0.35
    # Beams are used up to this range; a longer (or, if enabled, no-return) beam only
    # clears free space up to it, with no occupied update.
    max_range_m: PositiveFloat = 8.0
    free_on_no_return: bool = True
    # For thin structures (see LogOddsGrid): a return beyond hit_max_range_m (None: all
    # up to max_range_m) clears free space up to far_free_margin_m short of it and marks
    # nothing occupied (the LDS-02's sigma reaches a 5 cm cell at 3 m; the margin is
    # 2 sigma at 8 m), and the hit kernel leaves out the cells beyond the endpoint unless
    # kernel_beyond_hit.
    hit_max_range_m: PositiveFloat | None = None
    far_free_margin_m: NonNegativeFloat = 0.25
    kernel_beyond_hit: bool = True

    _bounds = ordered(
        ("log_odds_min", "log_odds_max", True), ("free_probability", "occupied_probability", True)
    )


class CostmapConfig(Section):
    """Exponential-decay costmap (eqs. 4.35-4.36) plus lethal inflation."""

    cost_max: PositiveFloat = 1.0
    decay_lambda_per_m: PositiveFloat = 5.0
    radius_m: PositiveFloat = 0.5
    unknown_cost: Probability = 0.5


class PlanningConfig(Section):
    """What the global and local planners share (thesis §4.7-4.8): the replanning and
    control rates, the horizon, the clearances, and stuck detection and recovery.

    The thesis names these parameters but gives no values; the defaults are ours, chosen
    for the TurtleBot3 Burger (radius 0.105 m, 0.22 m/s) on a 0.05 m grid, and tuned on
    the planning tests (head-on swap, obstacle bypass). Each planner's own parameters are
    in its section, ``algorithms.global_planner`` and ``algorithms.local_planner``.
    """

    replan_period_s: PositiveFloat = 2.0
    horizon_s: PositiveFloat = 2.0  # T_p (eqs. 4.48-4.50, 4.67)
    # Local planner rate: 10 Hz, a usual ROS local-planner rate and 5 sim steps of 0.02 s.
    control_period_s: PositiveFloat = 0.1
    # d_max^obs (eqs. 4.54, 4.63): ~3 robot radii, so the repulsion starts well before
    # contact yet a 0.9 m door (0.45 m to either side) exerts no push at its centre.
    obstacle_influence_m: PositiveFloat = 0.3
    # d_max^robot (eqs. 4.55, 4.65): robots repel within ~2.5 diameters.
    robot_influence_m: PositiveFloat = 0.55
    stuck_timeout_s: PositiveFloat = 10.0
    # Less than this gain in distance to the goal over stuck_timeout_s is "no progress".
    stuck_min_progress_m: PositiveFloat = 0.1
    # Recovery after a stuck event: reverse this far at this speed (the robot came in
    # forward, so the way back is free), then replan the path with the cost raised by
    # recovery_penalty_cost within recovery_penalty_radius_m of where it got stuck
    # (~ the size of a dead end a local planner falls into).
    recovery_back_off_m: PositiveFloat = 0.25
    recovery_back_off_mps: PositiveFloat = 0.1
    recovery_penalty_radius_m: PositiveFloat = 0.6
    recovery_penalty_cost: NonNegativeFloat = 10.0


class ServerConfig(Section):
    """How the centralized server schedules its pipeline (thesis Fig. 4.2)."""

    # Costmap and frontiers are refreshed at this period; SLAM, map and local planning
    # run every control period. 0.5 s lets a robot at 0.22 m/s move ~2 cells in between.
    map_update_period_s: PositiveFloat = 0.5
    # A robot within this path length of its frontier target has reached it.
    goal_tolerance_m: PositiveFloat = 0.3
    # Beams ending within robot radius + this margin of another robot's estimate are
    # dropped before mapping and matching: robots are not walls. The margin covers the two
    # robots' relative error: with 0.15 m, ten robots leaving one room fed each other's
    # returns into their matches once they were 0.15 m off, and the map came apart; with
    # 0.5 m, the thesis labs lost wall returns near teammates at the start.
    robot_filter_margin_m: NonNegativeFloat = 0.3
    # Costmap and planning use the known area's bounding box grown by this margin.
    window_margin_m: PositiveFloat = 1.0
    # Exploration is over when no robot has had a reachable frontier for this long.
    finish_after_idle_s: NonNegativeFloat = 4.0
    # After exploring, drive loops through the map for this long before the run ends
    # (0: end at once): the trajectory grows while the map does not, which shows whether
    # a cycle's cost follows the trajectory's length (acslam.exploration.patrol).
    patrol_s: NonNegativeFloat = 0.0
    # The patrol's waypoints cover the free space to within this distance.
    patrol_spacing_m: PositiveFloat = 4.0
    # With unknown relative starts, the frames' maps are tried for a merge this often.
    merge_period_s: PositiveFloat = 2.0


class ScanMatchingConfig(Section):
    """LiDAR scan matching: point-to-surface ICP, its covariance, verification, loop closures.

    The noise model defaults to :class:`LidarConfig`'s (the simulated LDS-02); for another
    sensor state its figures (a SICK LMS is ~0.01 m, no relative term). It weights each
    residual and gives the covariance, so a model that is too optimistic is caught by the
    residuals (the covariance is inflated when they exceed it), one too pessimistic is kept.
    Gates are ours: the correspondence gate shrinks from ``gate_initial_m`` by
    ``gate_decay`` per iteration to ``gate_min_m`` (never below ``inlier_sigmas`` predicted
    sigmas), so a 0.3 m / 0.2 rad initial error is pulled in first and outliers cut later.
    """

    range_noise_std_m: NonNegativeFloat = 0.005
    range_noise_rel: NonNegativeFloat = 0.015
    angle_noise_std_rad: NonNegativeFloat = 0.002
    # Residual sigmas never go below this (a noise-free model would divide by zero).
    min_sigma_m: PositiveFloat = 1e-4
    # Reference surfaces: PCA line of each point's k nearest neighbours within
    # line_max_extent_m, refined by a parabola (or, surface_fit "line", a line) fitted to
    # the same k; a neighbourhood whose PCA thickness exceeds line_planarity_sigmas
    # predicted sigmas (a corner, an edge, clutter) is not used.
    line_neighbors: Annotated[int, Field(ge=3)] = 9
    # One return per cell of this size (0: all), so dense near walls do not dominate.
    voxel_filter_m: NonNegativeFloat = 0.02
    # The least constrained axis counts only points whose normal's component along it
    # exceeds this many sigmas of the normal's direction (a wall beside the robot does not
    # constrain its length, whatever its fitted normals say).
    normal_tilt_sigmas: NonNegativeFloat = 3.0
    line_max_extent_m: PositiveFloat = 1.0
    line_planarity_sigmas: PositiveFloat = 3.0
    surface_fit: Literal["parabola", "line"] = "parabola"
    gate_initial_m: PositiveFloat = 1.0
    gate_min_m: PositiveFloat = 0.1
    gate_decay: Annotated[float, Field(gt=0, le=1)] = 0.7
    # Huber threshold on the whitened residual (95 % efficiency under Gaussian noise).
    huber_k: PositiveFloat = 1.345
    inlier_sigmas: PositiveFloat = 3.0
    max_iterations: Annotated[int, Field(ge=1)] = 50
    tolerance_m: PositiveFloat = 1e-6
    tolerance_rad: PositiveFloat = 1e-6
    # ... or when the step is below this many sigmas (its Mahalanobis length under H).
    tolerance_sigmas: PositiveFloat = 0.1
    min_correspondences: Annotated[int, Field(ge=3)] = 20
    # Weak prior at the initial guess: a direction the scans do not constrain (a corridor's
    # axis) stays at the guess with this sigma instead of an infinite one.
    prior_sigma_m: PositiveFloat = 10.0
    prior_sigma_rad: PositiveFloat = 3.0
    covariance_floor_m: PositiveFloat = 0.001
    covariance_floor_rad: PositiveFloat = 0.001
    # Verification of a match (all must hold).
    min_inlier_ratio: Probability = 0.6
    max_rms_m: PositiveFloat = 0.1
    max_correction_m: PositiveFloat = 0.5
    max_correction_rad: PositiveFloat = 0.35
    max_sigma_m: PositiveFloat = 0.05
    max_sigma_rad: PositiveFloat = 0.02
    max_condition: Annotated[float, Field(ge=1)] = 25.0
    # A sequential match must agree with the odometry it starts from: the squared
    # Mahalanobis distance of its correction under the odometry's and the match's
    # covariances summed is at most this (chi-square, 3 dof, 99.9 %; 0: not checked).
    # Teammates driving alongside fit as well as walls and say "not moved"; odometry
    # over one keyframe is far better than that.
    odometry_gate_chi2: NonNegativeFloat = 16.27
    # A verified loop closure is restarted this far either way along its least
    # constrained axis; where a restart settles elsewhere with as good a fit, the gap is
    # added to its covariance (0: no restarts). See scan_matching.with_restart_spread.
    restart_offset_m: NonNegativeFloat = 0.3
    # Besides the previous keyframe, each keyframe is matched to the latest one at least
    # this far back along the robot's path (0: not at all), see lidar_constraints.
    sequential_baseline_m: NonNegativeFloat = 1.0
    # A baseline match must agree with the previous-keyframe matches it spans, composed (a
    # rejected one enters as the estimate's step with its odometry's covariance): the
    # squared Mahalanobis distance under both covariances summed is at most this
    # (chi-square, 3 dof, 99.9 %; 0: not checked).
    baseline_chain_gate_chi2: NonNegativeFloat = 16.27
    # Loop-closure candidates: keyframes closer than this, and (same robot) further apart
    # in time than loop_min_separation_s so neighbours in the chain are not re-matched.
    loop_radius_m: PositiveFloat = 2.0
    loop_min_separation_s: NonNegativeFloat = 20.0
    # At most this many of the loop-closure pairs a search found are matched in one cycle
    # (0: all at once); the rest, in the search's order, in the next cycles. One match
    # takes ~3.3 ms (LDS-02 scans), so 8 keep it within a quarter of the 100 ms control
    # period; at once, 10 robots on office_a met up to 69 pairs in one search (200 ms).
    loop_matches_per_cycle: Annotated[int, Field(ge=0)] = 8
    # Sequential matches go against the merged scans of this many previous keyframes of
    # the robot (placed by their current estimates): more of the scene per match, as the
    # carmen preset uses for its 180-degree laser. 1: the previous keyframe's scan alone.
    # With the simulated LDS-02, five drift no less than one and their covariances are
    # overconfident (benchmarks/scan_matching_accuracy.py).
    submap_keyframes: Annotated[int, Field(ge=1)] = 1
    # Every scan besides its keyframe's first is matched to that first scan and placed by
    # the match instead of by odometry, when verified: each scan's pose, the trajectory a
    # replay writes and the map it composes, is then as good as the keyframes' (one ICP
    # per scan; the graph does not change).
    place_scans_by_matching: bool = False
    # Sequential and baseline matches use each keyframe's first this many scans, merged
    # into the reference and stacked as the query, so each waits for the keyframe to
    # close: it is made when the next keyframe opens (odometry carries the pose until
    # then). 1: the keyframe's first scan alone, matched at once. With the LDS-02, three
    # scans drift a third less in heading over 20 matches
    # (benchmarks/scan_matching_accuracy.py --keyframe-scans); the floor-plan examples
    # use 3 (README). A match whose keyframes saw a teammate uses their first scans.
    keyframe_scans: Annotated[int, Field(ge=1)] = 1


def _stage_section(kind: str) -> Any:
    """A stage section: ``{name: PLUGIN, ...}`` validated by that plugin's own Params.

    The plugin is looked up when a scenario is validated, not when this module is
    imported, so plugins registered later (entry points, tests) are accepted too.
    """

    def dispatch(value: Any, handler: Any) -> StageParams:
        from acslam.errors import PluginError
        from acslam.pipeline.registry import REGISTRIES

        registry = REGISTRIES[kind]
        if isinstance(value, StageParams):
            value = value.model_dump()
        if not isinstance(value, dict):
            raise PydanticCustomError(
                "stage_section", "must be a mapping with the plugin's name and parameters"
            )
        try:
            plugin = registry.get(value.get("name", registry.default))
        except PluginError as exc:
            raise PydanticCustomError("stage_section", str(exc)) from None
        return plugin.params.model_validate(value)

    def default() -> StageParams:
        from acslam.pipeline.registry import REGISTRIES

        return REGISTRIES[kind].default_params()

    return Annotated[
        SerializeAsAny[StageParams], WrapValidator(dispatch), Field(default_factory=default)
    ]


class AlgorithmsConfig(Section):
    """The server's stages, each chosen by name (``{name: ..., ...}``), and what they share."""

    localizer: _stage_section("localizer")
    mapper: _stage_section("mapper")
    frontier_detector: _stage_section("frontier_detector")
    clusterer: _stage_section("clusterer")
    allocator: _stage_section("allocator")
    global_planner: _stage_section("global_planner")
    local_planner: _stage_section("local_planner")
    costmap: CostmapConfig = CostmapConfig()
    planning: PlanningConfig = PlanningConfig()
    server: ServerConfig = ServerConfig()
    scan_matching: ScanMatchingConfig = ScanMatchingConfig()

    def with_stage(self, kind: str, name: str) -> AlgorithmsConfig:
        """The same algorithms with stage ``kind`` replaced by plugin ``name``: fields the
        scenario set in the current section that the new plugin also has are kept, every
        other field takes the new plugin's default."""
        from acslam.pipeline.registry import REGISTRIES

        current = getattr(self, kind)
        if current.name == name:
            return self
        params = REGISTRIES[kind].get(name).params
        kept = {
            k: getattr(current, k)
            for k in current.model_fields_set
            if k in params.model_fields and k != "name"
        }
        return self.model_copy(update={kind: params(name=name, **kept)})


# --------------------------------------------------------------------------- scenario


class ScenarioConfig(Section):
    """A whole scenario: world, team, sensors, algorithms, seed."""

    name: str = "scenario"
    description: str = ""
    seed: Annotated[int, Field(ge=0)] = 0
    world: WorldConfig
    landmarks: LandmarkConfig = LandmarkConfig()
    robots: RobotsConfig = RobotsConfig()
    sensors: SensorsConfig = SensorsConfig()
    sim: SimConfig = SimConfig()
    algorithms: AlgorithmsConfig = Field(default_factory=AlgorithmsConfig)


def builtin_scenario_names() -> list[str]:
    """Names of the scenarios shipped with acslam, sorted."""
    folder = resources.files("acslam") / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def _is_union_member(item: Any) -> bool:
    """A location item that names a member of a union type (``list[...]``,
    ``literal['random']``) rather than a field: field names hold no brackets."""
    return isinstance(item, str) and "[" in item


def _field_path(loc: tuple[Any, ...]) -> str:
    """Pydantic error location -> ``robots.starts[1]``, without union members' tags."""
    if len(loc) > 1 and loc[0] == "world" and isinstance(loc[1], str) and loc[1] in _WORLD_TAGS:
        loc = loc[:1] + loc[2:]
    loc = tuple(item for item in loc if not _is_union_member(item))
    parts: list[str] = []
    for item in loc:
        parts.append(f"[{item}]" if isinstance(item, int) else ("." if parts else "") + str(item))
    return "".join(parts)


def parse_scenario(data: Any, source: str | Path) -> ScenarioConfig:
    """Validate already-loaded YAML data; relative file paths resolve against ``source``."""
    if not isinstance(data, dict):
        raise ConfigError(source, "", "a scenario must be a YAML mapping of sections")
    config = validated(ScenarioConfig, data, source)
    _check_clock(config, source)
    world_file = getattr(config.world, "file", None)
    if world_file is not None and not world_file.is_absolute() and Path(source).is_file():
        resolved = (Path(source).parent / world_file).resolve()
        config = config.model_copy(
            update={"world": config.world.model_copy(update={"file": resolved})}
        )
    return config


def _check_clock(config: ScenarioConfig, source: str | Path) -> None:
    """``sim.dt_s`` no longer than the control period and every sensor period."""
    sensors = config.sensors
    periods_s = {
        "algorithms.planning.control_period_s": config.algorithms.planning.control_period_s,
        "the period of sensors.odometry.rate_hz": 1.0 / sensors.odometry.rate_hz,
        "the period of sensors.lidar.rate_hz": 1.0 / sensors.lidar.rate_hz,
        "the period of sensors.camera.rate_hz": 1.0 / sensors.camera.rate_hz,
    }
    name, period_s = min(periods_s.items(), key=lambda item: item[1])
    if config.sim.dt_s > period_s + 1e-12:
        raise ConfigError(
            source,
            "sim.dt_s",
            f"the step of {config.sim.dt_s:g} s is longer than {name} ({period_s:g} s)",
        )


def validated(model: type[BaseModel], data: Any, source: str | Path, prefix: str = "") -> Any:
    """``model`` from loaded YAML or JSON data; the first problem becomes a ConfigError
    naming ``source`` and the field path (under ``prefix``)."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        # A value no member of a union takes fails each; the literal members' failures
        # ("should be 'random'") say least about what is wrong with the value given.
        errors = [
            error
            for error in exc.errors()
            if not any(
                _is_union_member(item) and item.startswith("literal[") for item in error["loc"]
            )
        ] or exc.errors()
        first = errors[0]
        more = f" (and {plural(len(errors) - 1, 'more problem')})" if len(errors) > 1 else ""
        message = first["msg"].removeprefix("Value error, ")
        field = ".".join(p for p in (prefix, _field_path(first["loc"])) if p)
        raise ConfigError(source, field, message + more) from None


def load_algorithms(path: str | Path) -> AlgorithmsConfig:
    """An ``algorithms`` section on its own (a replay preset): stages and their
    parameters, every field not given at its default."""
    path = Path(path)
    data = read_yaml(path, "algorithms file")
    if not isinstance(data, dict):
        raise ConfigError(path, "", "an algorithms file must be a YAML mapping of sections")
    return validated(AlgorithmsConfig, data, path, "algorithms")


def load_scenario_config(name_or_path: str | Path) -> tuple[ScenarioConfig, str]:
    """Load a scenario by built-in name or YAML path; returns it with its source label."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") or path.exists():
        source = str(path)
        text = read_text(path, "scenario file")
    else:
        names = builtin_scenario_names()
        if str(name_or_path) not in names:
            raise ConfigError(
                str(name_or_path),
                "",
                "unknown scenario (not a file, not a built-in; built-ins: "
                + ", ".join(names)
                + ")",
            )
        source = f"<built-in {name_or_path}>"
        text = (resources.files("acslam") / "scenarios" / f"{name_or_path}.yaml").read_text(
            encoding="utf-8"
        )
    return parse_scenario(parse_yaml(text, source), source), source
