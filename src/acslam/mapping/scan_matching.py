"""LiDAR scan matching (thesis §4.4.1): point-to-surface ICP between two 2D scans.

Turns a pair of scans into a relative-pose constraint with a covariance for the SLAM
graph, between consecutive keyframes and between keyframes close in space (loop closures,
found by :mod:`acslam.slam.loop_candidates`), each accepted only when :func:`verify`
passes.

Design:

- Correspondences are exact nearest neighbours within the gate, from a grid of the
  reference's points built once per reference scan (:mod:`acslam.mapping.nearest_points`:
  cKDTree's answers at a fifth of its time). Brute force would cost N^2 distances per
  iteration; projective (beam-index) association breaks under occlusion, a different
  viewpoint or a different sensor layout. The neighbourhoods of the surface fits come
  from scipy's :class:`~scipy.spatial.cKDTree`.
- Point-to-surface, not point-to-point: two scans never sample a wall at the same places,
  so point-to-point is biased by the beam spacing; the distance to the surface is not.
  Each reference point's surface is a parabola o = a + b t + c t^2 fitted by least squares
  to its k nearest neighbours in the frame of their PCA line (t along it, o across): the
  fit averages the range noise over all k beams yet, unlike their centroid, does not lie
  inside a curved surface by the sagitta, and the residual follows the curve. On round
  plants the centroid line biased matches ~0.5 % along a row of them, the quadratic
  ~0.1 %. With few neighbours in clutter a parabola follows the clutter: ``surface_fit``
  "line" fits o = a + b t instead (the line through the neighbours' centroid). Thick
  neighbourhoods (corners, edges, clutter) are dropped.
- A voxel filter first keeps one return per ``voxel_filter_m`` cell, as Cartographer's
  does: a wall beside the robot is sampled every few millimetres, so its k neighbours span
  centimetres and their fitted normals tilt by degrees, and those points outweigh the
  whole rest of the scan. Thinned, the neighbourhoods span decimetres.
- Degenerate axis: the least constrained translation axis keeps only the information of
  surfaces that face along it (:func:`_without_untrusted_axis_information`); the rest of
  its information, a corridor's noisily fitted wall normals, is taken out of the
  covariance, and in a sequential match its share of the correction is undone, so
  odometry decides that axis there (the solution remapping of Zhang, Kaess & Singh 2016).
- Robustness: a metric gate on the correspondence distance shrinks over the iterations
  (large at first so a wrong initial guess is pulled in, small later to cut outliers),
  and Huber weights on the residual whitened by the sensor noise model.
- Teammates' shadows: the server drops the beams that end on other robots and keeps where
  they were as the scan's blind sectors; the inlier ratio that verification tests counts
  only the points of B that A could have seen (:func:`_visible_inlier_ratio`).
- Covariance (Censi 2007, "An accurate closed-form estimate of ICP's covariance"): the
  first-order propagation of the range and bearing noise of every beam of *both* scans
  through the weighted least-squares solution, H^-1 M H^-1 (a reference beam enters all
  residuals whose line's point it is part of, so shared noise is not counted as
  independent). It is inflated by the mean squared whitened inlier residual when that
  exceeds 1 (the noise model was too optimistic), a weak prior keeps unconstrained
  directions finite, and a floor is added.

Poses are ``[x, y, theta]`` (m, rad); a match returns scan B's sensor pose in A's frame,
i.e. ``geometry.between(pose_a, pose_b)`` for sensor poses in the world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from scipy.spatial import cKDTree

from acslam.config import ScanMatchingConfig
from acslam.geometry import between, transform_points, wrap_angle
from acslam.mapping.nearest_points import PointGrid, point_grid


@dataclass(frozen=True, eq=False)
class ScanPoints:
    """A scan's valid returns in its sensor frame: all a scan matched *to* another needs.

    Built by :func:`scan_points`; a scan matched only as the query (e.g. placed within its
    keyframe) skips the grid and surfaces a reference needs.
    """

    points_m: np.ndarray
    ranges_m: np.ndarray
    directions: np.ndarray


@dataclass(frozen=True, eq=False)
class PreparedScan(ScanPoints):
    """A scan's valid returns in its sensor frame, with what matching against it needs.

    Built once per scan by :func:`prepare_scan` (a keyframe's scan is matched many times).
    ``line_*`` describe, for each point, the surface fitted to its neighbourhood: the
    fitted surface point at the beam (``line_points_m``), its unit normal there, and
    ``line_curvature`` c of o = c t^2 along the tangent; ``line_support`` (N, k) are the
    beams of the fit and ``line_weights`` (N, k) their weights in the surface point's
    offset along the normal (summing to 1); ``line_ok`` is False where the neighbourhood
    is not a line, ``line_variance_m2`` the surface point's variance along the normal and
    ``line_normal_variance_rad2`` the variance of the normal's direction.
    ``blind_sectors`` (K, 3) ``[from_rad, to_rad, range_m]``: bearings where a teammate
    blocked the view, and the range it blocked from; beyond it the scan saw nothing.
    """

    grid: PointGrid
    line_points_m: np.ndarray
    line_normals: np.ndarray
    line_support: np.ndarray
    line_weights: np.ndarray
    line_ok: np.ndarray
    line_variance_m2: np.ndarray
    line_curvature: np.ndarray
    line_normal_variance_rad2: np.ndarray
    blind_sectors: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass(frozen=True)
class ScanMatchResult:
    """Outcome of :func:`match_scans`.

    ``relative`` is B's sensor pose in A's frame ``[dx_m, dy_m, dtheta_rad]`` and
    ``covariance`` its 3x3 covariance in the same order. ``inlier_ratio`` is the share of
    B's valid points whose final residual is within ``inlier_sigmas`` predicted sigmas;
    ``rms_residual_m`` is the RMS point-to-surface distance of those inliers.
    """

    relative: np.ndarray
    covariance: np.ndarray
    inlier_ratio: float
    rms_residual_m: float
    iterations: int
    converged: bool


@dataclass(frozen=True)
class Verification:
    """Whether a match is accepted, and why not (empty ``reasons`` when accepted)."""

    accepted: bool
    reasons: tuple[str, ...]

    def __bool__(self) -> bool:
        return self.accepted


def _beam_sigmas_m(ranges_m: np.ndarray, config: ScanMatchingConfig) -> tuple[np.ndarray, float]:
    """Range sigma per beam, and the bearing sigma, of the configured noise model."""
    return config.range_noise_std_m + config.range_noise_rel * ranges_m, config.angle_noise_std_rad


def scan_points(
    angles_rad: np.ndarray, ranges_m: np.ndarray, config: ScanMatchingConfig
) -> ScanPoints:
    """A scan's points; ``inf``/non-finite ranges dropped, and of the returns in one
    ``config.voxel_filter_m`` cell only the first kept."""
    angles_rad = np.asarray(angles_rad, dtype=float)
    ranges_m = np.asarray(ranges_m, dtype=float)
    valid = np.isfinite(ranges_m) & (ranges_m > 0.0)
    ranges = ranges_m[valid]
    directions = np.stack([np.cos(angles_rad[valid]), np.sin(angles_rad[valid])], axis=1)
    points = directions * ranges[:, None]
    if config.voxel_filter_m > 0.0 and len(points):
        cells = np.floor(points / config.voxel_filter_m).astype(np.int64)
        _, first = np.unique(cells, axis=0, return_index=True)
        kept = np.sort(first)
        ranges, directions, points = ranges[kept], directions[kept], points[kept]
    return ScanPoints(points, ranges, directions)


def prepare_scan(
    angles_rad: np.ndarray,
    ranges_m: np.ndarray,
    config: ScanMatchingConfig,
    blind_sectors: np.ndarray | None = None,
) -> PreparedScan:
    """Points (:func:`scan_points`), their grid and neighbourhood lines of a scan.
    ``blind_sectors``: where teammates blocked the view (:class:`PreparedScan`)."""
    blind = np.zeros((0, 3)) if blind_sectors is None else np.asarray(blind_sectors, float)
    returns = scan_points(angles_rad, ranges_m, config)
    points, ranges, directions = returns.points_m, returns.ranges_m, returns.directions
    grid = point_grid(points)
    k = min(config.line_neighbors, len(points))
    if k < 3:
        empty = np.zeros((len(points), 2))
        none = np.zeros(len(points))
        return PreparedScan(
            points, ranges, directions, grid, empty, empty,
            np.zeros((len(points), max(k, 1)), dtype=np.int64),
            np.zeros((len(points), max(k, 1))), np.zeros(len(points), dtype=bool), none, none,
            none, blind,
        )  # fmt: skip
    distances, neighbors = cKDTree(points).query(points, k=k)
    local = points[neighbors]
    centroids = local.mean(axis=1)
    offsets = local - centroids[:, None, :]
    sxx = np.mean(offsets[..., 0] ** 2, axis=1)
    syy = np.mean(offsets[..., 1] ** 2, axis=1)
    sxy = np.mean(offsets[..., 0] * offsets[..., 1], axis=1)
    # Closed-form 2x2 PCA: the normal is the minor axis, its eigenvalue the thickness^2.
    major = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    normals = np.stack([-np.sin(major), np.cos(major)], axis=1)
    spread = np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
    thickness_m2 = np.maximum(0.5 * (sxx + syy) - spread, 0.0)
    sigma_r, sigma_a = _beam_sigmas_m(ranges, config)
    point_sigma = np.maximum(np.sqrt(sigma_r**2 + (ranges * sigma_a) ** 2), config.min_sigma_m)
    line_ok = (distances[:, -1] <= config.line_max_extent_m) & (
        thickness_m2 <= (config.line_planarity_sigmas * point_sigma) ** 2
    )
    degree = 2 if config.surface_fit == "parabola" else 1
    anchors, normals, curvature, weights, slope_weights = _fit_surfaces(
        points, local, normals, degree
    )
    along = np.einsum("nkd,nd->nk", directions[neighbors], normals)
    variance = (
        along**2 * sigma_r[neighbors] ** 2 + (1.0 - along**2) * (ranges[neighbors] * sigma_a) ** 2
    )
    line_variance = np.sum(weights**2 * variance, axis=1)
    normal_variance = np.sum(slope_weights**2 * variance, axis=1)
    return PreparedScan(
        points, ranges, directions, grid, anchors, normals, neighbors, weights, line_ok,
        line_variance, curvature, normal_variance, blind,
    )  # fmt: skip


def merged_reference(
    scans: list[tuple[np.ndarray, ScanPoints]], config: ScanMatchingConfig
) -> PreparedScan:
    """One reference (a submap) from several scans, each given with its sensor pose in
    the reference's frame: their points merged, then prepared as one scan seen from the
    frame's origin."""
    points = np.vstack([transform_points(pose, scan.points_m) for pose, scan in scans])
    return prepare_scan(
        np.arctan2(points[:, 1], points[:, 0]), np.hypot(points[:, 0], points[:, 1]), config
    )


def stacked_scans(scans: list[tuple[np.ndarray, ScanPoints]]) -> ScanPoints:
    """One query from several scans, each given with its sensor pose in the first one's
    frame: their returns in that frame, as seen from its origin (one scan: itself)."""
    if len(scans) == 1:
        return scans[0][1]
    points = np.vstack([transform_points(pose, scan.points_m) for pose, scan in scans])
    ranges = np.hypot(points[:, 0], points[:, 1])
    return ScanPoints(points, ranges, points / ranges[:, None])


MIN_FIT_HADAMARD_RATIO = 1e-6
"""A fit whose (scaled) normal matrix is closer to singular than this (the neighbours
bunched at one place along the line) falls back to their centroid's line."""


def _fit_surfaces(
    points: np.ndarray, local: np.ndarray, normals: np.ndarray, degree: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit o = a + b t + c t^2 (``degree`` 2; c = 0 for 1, a line) to each point's
    neighbourhood ``local`` (N, k, 2), in the frame at the point with t along its PCA line
    and o along ``normals``.

    Returns the surface point p + a n, the unit normal there (n tilted by the slope b),
    the curvature term c in that frame, and each neighbour's weight in a (the intercept
    row of the least-squares solution, so the weights sum to 1) and in b (1/m; the
    normal's direction error is b's, to first order).
    """
    n_points, k = local.shape[:2]
    tangents = np.stack([normals[:, 1], -normals[:, 0]], axis=1)
    offsets = local - points[:, None, :]
    t = np.einsum("nkd,nd->nk", offsets, tangents)
    o = np.einsum("nkd,nd->nk", offsets, normals)
    scale = np.maximum(np.abs(t).max(axis=1), 1e-9)
    ts = t / scale[:, None]  # scaled so the normal matrix's columns are comparable
    design = np.stack([ts**power for power in range(degree + 1)], axis=2)
    gram = np.einsum("nki,nkj->nij", design, design)
    # Hadamard ratio det / prod(diagonal): 1 for orthogonal columns, 0 for dependent ones
    # (an eighth of the cost of a condition number by SVD).
    ok = np.linalg.det(gram) > MIN_FIT_HADAMARD_RATIO * np.prod(
        np.diagonal(gram, axis1=1, axis2=2), axis=1
    )
    solver = np.zeros((n_points, 3, k))
    solver[ok, : degree + 1] = np.linalg.solve(gram[ok], np.swapaxes(design[ok], 1, 2))
    solver[~ok, 0, :] = 1.0 / k  # centroid: a = mean(o), b = c = 0
    a, b, c = np.einsum("nik,nk->in", solver, o)
    b = b / scale
    c = c / scale**2
    tilted = normals - b[:, None] * tangents
    tilt = np.sqrt(1.0 + b * b)
    anchors = points + a[:, None] * normals
    slope_weights = solver[:, 1, :] / scale[:, None]
    return anchors, tilted / tilt[:, None], c / tilt**3, solver[:, 0, :], slope_weights


@numba.njit(cache=True, inline="always")
def _beam_variance_m2(
    along: float, range_m: float, range_std_m: float, range_rel: float, angle_std_rad: float
) -> float:
    """Variance of a beam endpoint along a surface normal: range noise along the beam and
    bearing noise across it, mixed by ``along`` (cosine of the beam-normal angle)."""
    sigma_r = range_std_m + range_rel * range_m
    return (
        along * along * sigma_r * sigma_r + (1.0 - along * along) * (range_m * angle_std_rad) ** 2
    )


OTHER_FACE_MIN_COSINE = 0.2
"""The two faces of a thin wall, seen from either side, are not one surface: aligning them
put a 0.15 m error with a 2 mm sigma into a sequential match of thesis-exp2 (3 robots,
Hungarian, seed 0) through a 0.15 m wall. A point is not matched to a surface when its
beam and the reference's beam hit that surface from opposite sides, each with a cosine to
the surface normal above this (more than about 12 degrees off grazing): nearer grazing,
the side is down to the normal's noise (the vineyard's plants), and such a beam says
little across the surface anyway."""


@numba.njit(cache=True)
def _accumulate(
    pose: np.ndarray,
    points: np.ndarray,
    directions: np.ndarray,
    ranges: np.ndarray,
    match: np.ndarray,
    match_distance: np.ndarray,
    centroids: np.ndarray,
    normals: np.ndarray,
    reference_directions: np.ndarray,
    line_ok: np.ndarray,
    line_variance: np.ndarray,
    curvature: np.ndarray,
    params: np.ndarray,
    weighted_jacobians: np.ndarray,
    residuals: np.ndarray,
    sigmas: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Gauss-Newton normal equations of the gated, Huber-weighted point-to-surface cost.

    The residual of a point at offset d from its reference surface point is
    n.d - c (t.d)^2 (t the tangent): its distance to the fitted parabola, to first order.

    A point is not matched to a surface its beam hits from the other side than the
    reference's beam did (:data:`OTHER_FACE_MIN_COSINE`).

    ``params`` = [gate_m, huber_k, range_std_m, range_rel, angle_std_rad, min_sigma_m,
    inlier_sigmas]. Fills per-point ``weighted_jacobians`` (w_i J_i, zero when rejected),
    ``residuals`` and ``sigmas`` for the covariance; returns H, g and the inlier count.
    """
    gate, huber_k, range_std, range_rel, angle_std, min_sigma, inlier_sigmas = (
        params[0], params[1], params[2], params[3], params[4], params[5], params[6]
    )  # fmt: skip
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    hessian = np.zeros((3, 3))
    gradient = np.zeros(3)
    inliers = 0
    for i in range(points.shape[0]):
        weighted_jacobians[i, 0] = 0.0
        weighted_jacobians[i, 1] = 0.0
        weighted_jacobians[i, 2] = 0.0
        residuals[i] = 0.0
        sigmas[i] = 1.0
        j = match[i]
        if j < 0 or not line_ok[j]:
            continue
        rx = c * points[i, 0] - s * points[i, 1]
        ry = s * points[i, 0] + c * points[i, 1]
        nx = normals[j, 0]
        ny = normals[j, 1]
        dx = rx + pose[0] - centroids[j, 0]
        dy = ry + pose[1] - centroids[j, 1]
        t = ny * dx - nx * dy
        r = nx * dx + ny * dy - curvature[j] * t * t
        ux = c * directions[i, 0] - s * directions[i, 1]
        uy = s * directions[i, 0] + c * directions[i, 1]
        along = nx * ux + ny * uy
        along_reference = nx * reference_directions[j, 0] + ny * reference_directions[j, 1]
        if along * along_reference < 0.0 and min(abs(along), abs(along_reference)) > (
            OTHER_FACE_MIN_COSINE
        ):
            continue  # the other face of the surface
        variance = (
            _beam_variance_m2(along, ranges[i], range_std, range_rel, angle_std) + line_variance[j]
        )
        sigma = max(math.sqrt(variance), min_sigma)
        if match_distance[i] > max(gate, inlier_sigmas * sigma) or abs(r) > max(
            gate, inlier_sigmas * sigma
        ):
            continue
        z = abs(r) / sigma
        if z <= inlier_sigmas:
            inliers += 1
        weight = (1.0 if z <= huber_k else huber_k / z) / (sigma * sigma)
        # d r / d (point): the parabola's normal at the point's projection (unnormalised).
        bend = 2.0 * curvature[j] * t
        jac0 = nx - bend * ny
        jac1 = ny + bend * nx
        jac2 = -jac0 * ry + jac1 * rx
        residuals[i] = r
        sigmas[i] = sigma
        weighted_jacobians[i, 0] = weight * jac0
        weighted_jacobians[i, 1] = weight * jac1
        weighted_jacobians[i, 2] = weight * jac2
        jac = (jac0, jac1, jac2)
        for a in range(3):
            gradient[a] += weight * jac[a] * r
            for b in range(3):
                hessian[a, b] += weight * jac[a] * jac[b]
    return hessian, gradient, inliers


@numba.njit(cache=True)
def _noise_information(
    pose: np.ndarray,
    query_directions: np.ndarray,
    query_ranges: np.ndarray,
    match: np.ndarray,
    weighted_jacobians: np.ndarray,
    reference_directions: np.ndarray,
    reference_ranges: np.ndarray,
    normals: np.ndarray,
    neighbors: np.ndarray,
    neighbor_weights: np.ndarray,
    params: np.ndarray,
) -> np.ndarray:
    """M = sum over the beams of both scans of (dg/dnoise) (dg/dnoise)^T sigma^2.

    g = sum_i w_i J_i r_i; a query beam moves only its own residual, a reference beam
    moves every residual matched to a surface it was fitted into, by its weight in that
    surface point (``neighbor_weights``).
    ``params`` = [range_std_m, range_rel, angle_std_rad].
    """
    range_std, range_rel, angle_std = params[0], params[1], params[2]
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    k = neighbors.shape[1]
    n_ref = reference_ranges.shape[0]
    by_range = np.zeros((n_ref, 3))
    by_bearing = np.zeros((n_ref, 3))
    info = np.zeros((3, 3))
    for i in range(query_ranges.shape[0]):
        j = match[i]
        if j < 0 or (
            weighted_jacobians[i, 0] == 0.0
            and weighted_jacobians[i, 1] == 0.0
            and weighted_jacobians[i, 2] == 0.0
        ):
            continue
        nx = normals[j, 0]
        ny = normals[j, 1]
        ux = c * query_directions[i, 0] - s * query_directions[i, 1]
        uy = s * query_directions[i, 0] + c * query_directions[i, 1]
        along = nx * ux + ny * uy
        variance = _beam_variance_m2(along, query_ranges[i], range_std, range_rel, angle_std)
        for a in range(3):
            for b in range(3):
                info[a, b] += weighted_jacobians[i, a] * weighted_jacobians[i, b] * variance
        for m in range(k):
            beam = neighbors[j, m]
            ref_along = nx * reference_directions[beam, 0] + ny * reference_directions[beam, 1]
            ref_across = -nx * reference_directions[beam, 1] + ny * reference_directions[beam, 0]
            for a in range(3):
                by_range[beam, a] -= weighted_jacobians[i, a] * ref_along * neighbor_weights[j, m]
                by_bearing[beam, a] -= (
                    weighted_jacobians[i, a] * ref_across * neighbor_weights[j, m]
                )
    for beam in range(n_ref):
        sigma_r = range_std + range_rel * reference_ranges[beam]
        sigma_t = reference_ranges[beam] * angle_std
        for a in range(3):
            for b in range(3):
                info[a, b] += (
                    by_range[beam, a] * by_range[beam, b] * sigma_r * sigma_r
                    + by_bearing[beam, a] * by_bearing[beam, b] * sigma_t * sigma_t
                )
    return info


@dataclass
class _Residuals:
    """Per query point, what the last accumulation left: whitened Jacobian rows, residuals
    and their sigmas (zero rows: no correspondence)."""

    weighted_jacobians: np.ndarray
    residuals: np.ndarray
    sigmas: np.ndarray

    @classmethod
    def empty(cls, count: int) -> _Residuals:
        return cls(np.zeros((count, 3)), np.zeros(count), np.ones(count))

    def _norms(self) -> np.ndarray:
        return self.weighted_jacobians[:, 0] ** 2 + self.weighted_jacobians[:, 1] ** 2

    def matched(self) -> np.ndarray:
        return self._norms() > 0

    def matched_count(self) -> int:
        return int(np.count_nonzero(self._norms()))


def _linearize(
    pose: np.ndarray,
    reference: PreparedScan,
    query: ScanPoints,
    params: np.ndarray,
    out: _Residuals,
) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """Correspondences within the gate ``params[0]`` at ``pose``, and the data term's
    Hessian, gradient and inlier count there; also returns the matches."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    moved = query.points_m @ np.array([[c, s], [-s, c]]) + pose[:2]
    distance, match = reference.grid.nearest_within(moved, params[0])
    hessian, gradient, inliers = _accumulate(
        pose, query.points_m, query.directions, query.ranges_m, match, distance,
        reference.line_points_m, reference.line_normals, reference.directions, reference.line_ok,
        reference.line_variance_m2, reference.line_curvature, params, out.weighted_jacobians,
        out.residuals, out.sigmas,
    )  # fmt: skip
    return hessian, gradient, inliers, match


def _settings(config: ScanMatchingConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The prior's information at the guess, the noise model, the kernel parameters."""
    prior = np.diag(
        [config.prior_sigma_m**-2, config.prior_sigma_m**-2, config.prior_sigma_rad**-2]
    )
    noise = np.array([config.range_noise_std_m, config.range_noise_rel, config.angle_noise_std_rad])
    params = np.array(
        [0.0, config.huber_k, *noise, config.min_sigma_m, config.inlier_sigmas], dtype=float
    )
    return prior, noise, params


def match_scans(
    reference: PreparedScan,
    query: ScanPoints,
    initial_guess: np.ndarray,
    config: ScanMatchingConfig,
    guess_from_odometry: bool = False,
) -> ScanMatchResult:
    """Align ``query`` (scan B) to ``reference`` (scan A) starting from ``initial_guess``.

    ``initial_guess`` is B's sensor pose in A's frame, e.g. from odometry. Gauss-Newton on
    the Huber-weighted point-to-surface cost plus a weak prior at the guess; converged when
    the gate has shrunk to its floor and the step is below the tolerances.
    ``guess_from_odometry``: the guess is odometry's over a short way, so along an axis
    the scans barely constrain it is kept (:func:`_without_untrusted_axis_information`).
    """
    initial = np.asarray(initial_guess, dtype=float).copy()
    prior, noise, params = _settings(config)
    out = _Residuals.empty(len(query.points_m))
    enough = len(reference.points_m) >= 3 and len(query.points_m) >= config.min_correspondences
    if not enough:
        return ScanMatchResult(initial, np.linalg.inv(prior), 0.0, math.inf, 0, False)
    pose, iterations, converged = _iterate(reference, query, initial, config, prior, params, out)
    if iterations == 0:
        return ScanMatchResult(initial, np.linalg.inv(prior), 0.0, math.inf, 0, False)
    # Statistics and covariance at the final pose (residuals refreshed there).
    data_hessian, _, inlier_count, match = _linearize(pose, reference, query, params, out)
    whitened = np.abs(out.residuals) / out.sigmas
    inliers = out.matched() & (whitened <= config.inlier_sigmas)
    info = _noise_information(
        pose, query.directions, query.ranges_m, match, out.weighted_jacobians,
        reference.directions, reference.ranges_m, reference.line_normals,
        reference.line_support, reference.line_weights, noise,
    )  # fmt: skip
    hessian_inv = np.linalg.inv(data_hessian + prior)
    covariance = hessian_inv @ (info + prior) @ hessian_inv
    if inlier_count > 0:
        covariance *= max(1.0, float(np.mean(whitened[inliers] ** 2)))
    covariance, pose = _without_untrusted_axis_information(
        covariance, pose, initial, prior, out, inliers,
        reference.line_normal_variance_rad2[match[inliers]], config.normal_tilt_sigmas,
        guess_from_odometry,
    )  # fmt: skip
    covariance = 0.5 * (covariance + covariance.T) + np.diag(
        [config.covariance_floor_m**2, config.covariance_floor_m**2, config.covariance_floor_rad**2]
    )
    rms = float(np.sqrt(np.mean(out.residuals[inliers] ** 2))) if inlier_count else math.inf
    return ScanMatchResult(
        relative=pose,
        covariance=covariance,
        inlier_ratio=_visible_inlier_ratio(pose, reference, query, inlier_count, inliers),
        rms_residual_m=rms,
        iterations=iterations,
        converged=converged,
    )


def _visible_inlier_ratio(
    pose: np.ndarray,
    reference: PreparedScan,
    query: ScanPoints,
    inlier_count: int,
    inliers: np.ndarray,
) -> float:
    """The share of B's points that fit A, counting only points A could have seen: a
    point behind a teammate that blocked A's view has nothing in A to fit. In a crowded
    team a quarter of each scan can be teammates, whose shadows differ between two scans;
    counted, they fail sequential matches that fit well where both scans saw."""
    count = len(query.points_m)
    if len(reference.blind_sectors) == 0:
        return inlier_count / count
    hidden = _behind_blind_sectors(transform_points(pose, query.points_m), reference.blind_sectors)
    seen = count - int(np.count_nonzero(hidden))
    if seen == 0:
        return 0.0
    return (inlier_count - int(np.count_nonzero(inliers & hidden))) / seen


def _behind_blind_sectors(points_m: np.ndarray, sectors: np.ndarray) -> np.ndarray:
    """Per point (sensor frame), whether it lies in a blind sector beyond its range."""
    bearing = np.arctan2(points_m[:, 1], points_m[:, 0])[:, None]
    distance_m = np.hypot(points_m[:, 0], points_m[:, 1])[:, None]
    offset = wrap_angle(bearing - sectors[None, :, 0])
    width = sectors[None, :, 1] - sectors[None, :, 0]
    return np.any((offset >= 0.0) & (offset <= width) & (distance_m > sectors[None, :, 2]), axis=1)


def _without_untrusted_axis_information(
    covariance: np.ndarray,
    pose: np.ndarray,
    initial: np.ndarray,
    prior: np.ndarray,
    out: _Residuals,
    inliers: np.ndarray,
    normal_variance_rad2: np.ndarray,
    tilt_sigmas: float,
    guess_from_odometry: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The match's covariance and pose with its least constrained translation axis left
    only the information of the surfaces that face along it.

    A point constrains an axis through its surface normal's component along it. On a
    straight wall beside the robot that component is the normal's fitting noise, yet
    hundreds of such points sum to centimetre sigmas along a corridor, and ICP slides
    along the wall to wherever the noise points: in the office_f floor plan, sequential
    matches 0.1-0.4 m off with 2-30 mm sigmas, over 80 % of their information from
    normals within 10 degrees of perpendicular to the axis. A point is trusted on the axis
    only where its normal's component along it exceeds ``tilt_sigmas`` sigmas of the
    normal's direction (``normal_variance_rad2``, of the reference surface it matched):
    door jambs, wall ends. The rest of the axis's information (above the prior) is taken
    out of the information matrix, where a slightly misplaced axis cannot turn into
    variance across the corridor.

    With a guess from odometry (a sequential match), the untrusted share of the correction
    along the axis is undone as well, as in the solution remapping of Zhang, Kaess & Singh
    (2016): the walls' noise moved it, and there the guess is odometry's over a short way.
    A corridor keeps odometry's position along it, a room the scans'. The shift's square
    is added to the axis's variance. A loop closure's guess has drifted, so its correction
    stands, with the covariance above. Measured on office_f's sequential matches (seed 1),
    against the truth: weighing the correction against odometry's covariance instead left
    16 of the 70 that had slid more than 5 cm still that far off (this rule: 3), and
    re-solving the axis from the trusted points alone, in the iterations or after, was
    worse still (the few noisy normals that pass the test then decide it).
    """
    information = np.linalg.inv(covariance)
    # The axis the position is least sure of, theta marginalised out (Schur complement).
    xy_information = (
        information[:2, :2] - np.outer(information[:2, 2], information[2, :2]) / information[2, 2]
    )
    eigenvalues, eigenvectors = np.linalg.eigh(xy_information)
    axis = np.array([eigenvectors[0, 0], eigenvectors[1, 0], 0.0])
    # weighted_jacobians are w J with the unit normal as J's translation part: w is a
    # row's translation norm, and a point's information on the axis (w J.axis)^2 / w.
    rows = out.weighted_jacobians[inliers]
    weights = np.hypot(rows[:, 0], rows[:, 1])
    along = rows @ axis
    points_information = np.divide(along**2, weights, out=np.zeros_like(along), where=weights > 0)
    total = float(np.sum(points_information))
    if total <= 0.0:
        return covariance, pose
    facing = np.abs(along) >= tilt_sigmas * np.sqrt(normal_variance_rad2) * weights
    untrusted_share = 1.0 - float(np.sum(points_information[facing])) / total
    removed = untrusted_share * max(eigenvalues[0] - float(axis @ prior @ axis), 0.0)
    information -= removed * np.outer(axis, axis)
    covariance = np.linalg.inv(information)
    if not guess_from_odometry:
        return covariance, pose
    shift_m = removed / eigenvalues[0] * float((initial - pose) @ axis)
    # Where the data's optimum lay is as likely as where the shift put the estimate.
    return covariance + shift_m**2 * np.outer(axis, axis), pose + shift_m * axis


def _iterate(
    reference: PreparedScan,
    query: ScanPoints,
    initial: np.ndarray,
    config: ScanMatchingConfig,
    prior: np.ndarray,
    params: np.ndarray,
    out: _Residuals,
) -> tuple[np.ndarray, int, bool]:
    """Gauss-Newton from ``initial`` with a shrinking gate; returns the pose, the
    iterations run and whether it converged (``params[0]`` is left at the last gate)."""
    pose = initial.copy()
    gate_m = config.gate_initial_m
    two_back: np.ndarray | None = None
    iterations = 0
    while iterations < config.max_iterations:
        iterations += 1
        at_floor = gate_m <= config.gate_min_m
        gate_m = max(config.gate_min_m, gate_m)
        params[0] = gate_m
        data_hessian, gradient, _, _ = _linearize(pose, reference, query, params, out)
        if out.matched_count() < config.min_correspondences:
            break
        offset = pose - initial
        offset[2] = wrap_angle(offset[2])
        step = -np.linalg.solve(data_hessian + prior, gradient + prior @ offset)
        pose += step
        pose[2] = wrap_angle(pose[2])
        gate_m *= config.gate_decay
        small = (
            math.hypot(step[0], step[1]) < config.tolerance_m
            and abs(step[2]) < config.tolerance_rad
        ) or float(step @ data_hessian @ step) < config.tolerance_sigmas**2
        # Correspondences flipping back and forth can leave a 2-cycle: stop at its midpoint.
        cycle = pose - two_back if two_back is not None else np.full(3, 1.0)
        cycle[2] = wrap_angle(cycle[2])
        if at_floor and float(cycle @ data_hessian @ cycle) < config.tolerance_sigmas**2:
            pose -= 0.5 * step
            small = True
        if at_floor and small:
            return pose, iterations, True
        two_back = pose - step
    return pose, iterations, False


def with_restart_spread(
    reference: PreparedScan,
    query: ScanPoints,
    result: ScanMatchResult,
    config: ScanMatchingConfig,
) -> ScanMatchResult:
    """``result`` with the spread of two restarts added to its covariance.

    The covariance of one match is the curvature of the cost at its minimum, which says
    nothing of other minima. Along a corridor whose walls carry small repeated features,
    a match settles within millimetres of wherever it starts, and each minimum is tight:
    in the office_f floor plan such matches were 0.2-0.9 m off along the corridor with
    sigmas of 8-17 mm, and the inter-robot ones among them bent the map by metres. ICP
    is therefore restarted ``config.restart_offset_m`` either way along the least
    constrained axis; a restart that ends at a fit as good (converged, inliers and RMS
    residual within :func:`verify`'s bounds, however far it went) adds the outer product
    of its offset from ``result``, as one sample of where the solution may lie. A unique
    minimum pulls the restarts back, adding almost nothing; a flat or repeated one widens
    that axis, and strict verification rejects the match. Loop closures use this
    (:mod:`acslam.slam.lidar_constraints`); sequential matches do not: in the office_a
    floor plan, giving their corridor axis up to odometry as well made the worst RMSE
    0.21 m, against 0.13 m with restarts of loop closures alone. In thesis-exp1 a loop
    closure 0.4 m off kept its 1 cm sigma because its one rival, 0.3 m further, lay
    beyond the correction bound from the initial guess: that bound is about the guess,
    not about rivals, so it is not applied here.
    """
    if config.restart_offset_m == 0.0 or not result.converged:
        return result
    weakest = np.linalg.eigh(result.covariance[:2, :2])[1][:, -1]
    covariance = result.covariance.copy()
    for side in (-1.0, 1.0):
        start = result.relative.copy()
        start[:2] += side * config.restart_offset_m * weakest
        restart = match_scans(reference, query, start, config)
        if verify(restart, result.relative, config, strict=False, max_correction_m=math.inf):
            gap = restart.relative[:2] - result.relative[:2]
            covariance[:2, :2] += np.outer(gap, gap)
    return replace(result, covariance=covariance)


def disagreement_sq(
    result: ScanMatchResult, expected: np.ndarray, expected_covariance: np.ndarray
) -> float:
    """Squared Mahalanobis distance between a match and another estimate of the same
    relative pose, under both covariances summed."""
    offset = np.asarray(result.relative, dtype=float) - np.asarray(expected, dtype=float)
    offset[2] = wrap_angle(float(offset[2]))
    combined = np.asarray(expected_covariance, dtype=float) + result.covariance
    return float(offset @ np.linalg.solve(combined, offset))


def verify(
    result: ScanMatchResult,
    initial_guess: np.ndarray,
    config: ScanMatchingConfig,
    strict: bool = True,
    max_correction_m: float | None = None,
    guess_covariance: np.ndarray | None = None,
) -> Verification:
    """Accept a match only if it converged, enough of B fits A closely, the correction
    from the initial guess is plausible and (``strict``) the covariance is small and well
    conditioned.

    A wrong loop closure corrupts the whole graph, while a rejected one only loses some
    information, so every test must pass. ``strict=False`` is for sequential matches: a
    corridor leaves the axis unconstrained, which the covariance says (the graph then
    takes that direction from odometry); rejecting it would drop the heading and the
    cross-axis position, which the corridor constrains best. ``max_correction_m``
    overrides ``config.max_correction_m`` (a loop after a long way may have drifted more).
    ``guess_covariance`` (3x3, x y theta; x and y isotropic, so in either scan's frame):
    the guess is odometry's, and the correction must agree with it within
    ``config.odometry_gate_chi2``.
    """
    limit_m = config.max_correction_m if max_correction_m is None else max_correction_m
    reasons: list[str] = []
    if not result.converged:
        reasons.append("did not converge")
    if result.inlier_ratio < config.min_inlier_ratio:
        reasons.append(f"inlier ratio {result.inlier_ratio:.2f} < {config.min_inlier_ratio}")
    if not result.rms_residual_m <= config.max_rms_m:
        reasons.append(f"RMS residual {result.rms_residual_m:.3f} m > {config.max_rms_m} m")
    correction = between(np.asarray(initial_guess, dtype=float), result.relative)
    if math.hypot(correction[0], correction[1]) > limit_m:
        reasons.append(f"translation correction > {limit_m:.2f} m")
    if abs(correction[2]) > config.max_correction_rad:
        reasons.append(f"rotation correction > {config.max_correction_rad} rad")
    if guess_covariance is not None and config.odometry_gate_chi2 > 0.0:
        distance_sq = disagreement_sq(result, initial_guess, guess_covariance)
        if not distance_sq <= config.odometry_gate_chi2:
            reasons.append(
                f"disagrees with odometry (Mahalanobis^2 {distance_sq:.1f} > "
                f"{config.odometry_gate_chi2:g})"
            )
    if not strict:
        return Verification(not reasons, tuple(reasons))
    xy_eigen = np.linalg.eigvalsh(result.covariance[:2, :2])
    if math.sqrt(xy_eigen[-1]) > config.max_sigma_m:
        reasons.append(f"translation sigma {math.sqrt(xy_eigen[-1]):.3f} m > {config.max_sigma_m}")
    if math.sqrt(result.covariance[2, 2]) > config.max_sigma_rad:
        reasons.append(f"rotation sigma > {config.max_sigma_rad} rad")
    if xy_eigen[-1] > config.max_condition * xy_eigen[0]:
        reasons.append(f"translation covariance condition > {config.max_condition:g}")
    return Verification(not reasons, tuple(reasons))
