"""Merging two maps whose relative pose is unknown: find it, verify it, compose.

Two robots that start apart each map in their own frame. Where does map B lie in map A?
B's surfaces are thinned to points and matched globally against A's likelihood field
(:mod:`acslam.mapping.correlative`: every position at every heading, exactly, by branch
and bound). B's walls must not cross what A saw empty, so a pose that puts more than
``max_contradiction`` of B's points, or a wall of ``max_contradicting_wall_m``, in A's
free space is passed over for the next best.
A wrong merge is worse than a late one, so the best pose left is accepted only if

- enough of B's points lie on A's surfaces (``min_matched_points``): real overlap, not a
  few walls that happen to fit;
- every other pose that scores nearly as well (``max_second_ratio``) and lies at least
  ``distinct_m`` or ``distinct_rad`` away is ruled out by free space: at it, clearly
  more of B's walls stand where A saw nothing (``refuting_points`` and
  ``refuting_share`` of B's points more). In a symmetric building two poses fit
  equally, and which one is right cannot be told until a map holds what breaks the
  symmetry.

The merged map is A's grid grown to hold B; a cell one map left unknown takes the
other's value, and where they disagree, occupied wins (what a planner must avoid).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from functools import partial

import numpy as np
from scipy import ndimage
from scipy.optimize import minimize
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from acslam.geometry import between, transform_points
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, window_around
from acslam.mapping.correlative import (
    HeadingTable,
    LikelihoodPyramid,
    Match,
    SearchWindow,
    best_match,
    surface_cells,
)


@dataclass(frozen=True)
class MergeParams:
    """How the match is searched and what it must show to be accepted."""

    # The likelihood field's width: a point this far from A's surface scores e^-0.5.
    sigma_m: float = 0.1
    # Levels of the branch-and-bound pyramid: the coarsest block is 2^depth cells.
    depth: int = 7
    # B's surfaces thinned to one point per square of this side.
    point_spacing_m: float = 0.1
    min_matched_points: int = 100
    max_contradiction: float = 0.1
    # A wall of B this long in A's free space refutes a pose however few points it has:
    # in two rooms alike but for a shelf, the half-turned pose put the 2.5 m shelf in the
    # other room's free space with 54 of B's 700 points (under 10 %) and merged 7.6 m
    # off. Shorter ones are not evidence: a teammate seen standing is 0.2 m across, and
    # two SLAM maps of the IPA lab disagreed along 1.0-1.5 m at their true pose.
    max_contradicting_wall_m: float = 1.5
    # Another pose is a rival when it scores at least this share of the best and lies
    # distinct_m or distinct_rad away; a rival is ruled out by more of B's points in A's
    # free space than the best pose has: refuting_points more, and refuting_share of all
    # of B's points more. Two SLAM maps of a floor disagree in about 1 % of their wall
    # points even where they fit (teammates seen standing, drift): in office_e, with
    # its rows of like offices, a wrong pose (44 of 4,952 points in A's free space) was
    # once taken over a rival wrong pose with 82, and merged 24 m off. Up to
    # max_alternatives rivals are examined.
    max_second_ratio: float = 0.9
    distinct_m: float = 1.0
    distinct_rad: float = 0.35
    refuting_points: int = 10
    refuting_share: float = 0.02
    max_alternatives: int = 5


@dataclass(frozen=True)
class MergeDecision:
    """The search's answer: ``pose`` is B's frame in A's frame (``[x, y, theta]``, m, rad)
    when one was found; ``accepted`` says whether it passed every check, ``reason`` why
    not. ``matched_points``: B's points within ``sigma_m`` of A's surfaces;
    ``contradiction``: the share of B's points in A's free space, away from its surfaces;
    ``second_score``: the best rival pose's score (0 if none came near)."""

    accepted: bool
    reason: str
    pose: np.ndarray | None
    score: float
    second_score: float
    matched_points: int
    points: int
    contradiction: float
    angle_step_rad: float
    resolution_m: float

    def as_dict(self) -> dict:
        """The decision as JSON-ready values (``pose_b_in_a``: the pose as a list)."""
        fields = asdict(self)
        pose = fields.pop("pose")
        return {**fields, "pose_b_in_a": None if pose is None else [float(v) for v in pose]}


def surface_points(values: np.ndarray, spec: GridSpec, spacing_m: float) -> np.ndarray:
    """(N, 2) centres of the map's surface cells, one per ``spacing_m`` square."""
    rows, cols = np.nonzero(surface_cells(values))
    xy = spec.cell_to_world(np.stack([rows, cols], axis=1))
    bins = np.floor(xy / spacing_m).astype(np.int64)
    _, first = np.unique(bins, axis=0, return_index=True)
    return xy[np.sort(first)]


def _lookup(values: np.ndarray, spec: GridSpec, points_m: np.ndarray) -> np.ndarray:
    """Each point's cell value; UNKNOWN beyond the grid."""
    cells = spec.world_to_cell(points_m)
    inside = spec.contains(cells)
    out = np.full(len(points_m), UNKNOWN, dtype=np.int8)
    out[inside] = values[cells[inside, 0], cells[inside, 1]]
    return out


def _free_space_hits(
    values_a: np.ndarray, spec_a: GridSpec, pyramid: LikelihoodPyramid, placed_m: np.ndarray
) -> np.ndarray:
    """Which of B's points land in A's free space, more than two sigma from its surfaces."""
    far = pyramid.likelihood_at(placed_m) < math.exp(-2.0)
    return far & (_lookup(values_a, spec_a, placed_m) == FREE)


def longest_wall_m(points_m: np.ndarray, link_m: float) -> float:
    """The largest extent (bounding-box diagonal) of a chain of points, each within
    ``link_m`` of the next."""
    if len(points_m) < 2:
        return 0.0
    pairs = cKDTree(points_m).query_pairs(link_m, output_type="ndarray")
    links = coo_matrix(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points_m),) * 2
    )
    _, labels = connected_components(links, directed=False)
    extents = [np.ptp(points_m[labels == k], axis=0) for k in np.unique(labels)]
    return float(max(np.hypot(*extent) for extent in extents))


@dataclass(frozen=True)
class Pin:
    """A sighting's word on where B lies: B's point ``b_xy_m`` (where a robot of B stood)
    lies within ``half_size_m`` (per axis) of A's point ``a_xy_m`` (where a robot of A saw
    it), at a heading the sighting does not tell. Only B's surfaces within ``reach_m`` of
    ``b_xy_m`` are matched: the place the two robots met, which both have seen."""

    a_xy_m: np.ndarray
    b_xy_m: np.ndarray
    half_size_m: float
    reach_m: float


def find_merge(
    values_a: np.ndarray,
    spec_a: GridSpec,
    values_b: np.ndarray,
    spec_b: GridSpec,
    params: MergeParams | None = None,
    pin: Pin | None = None,
) -> MergeDecision:
    """Where map B lies in map A, searched at every heading over all of A, or only where
    ``pin`` puts it, and verified."""
    params = params or MergeParams()
    points = surface_points(values_b, spec_b, params.point_spacing_m)
    if pin is not None:
        points = points[np.hypot(*(points - pin.b_xy_m).T) <= pin.reach_m]
    empty = MergeDecision(
        False, "", None, 0.0, 0.0, 0, len(points), 0.0, math.nan, spec_a.resolution_m
    )
    if len(points) == 0:
        near = "" if pin is None else f" within {pin.reach_m:g} m of the pinned point"
        return replace(empty, reason=f"map B has no occupied cells to match{near}")
    if len(points) < params.min_matched_points:
        return replace(
            empty,
            reason=f"too little overlap: B has {len(points)} surface points, "
            f"{params.min_matched_points} needed on A's surfaces",
        )
    if pin is None:
        window = SearchWindow.covering(spec_a, points)
    else:
        window = SearchWindow.pinned(pin.b_xy_m, pin.a_xy_m, pin.half_size_m)
        # Every pose searched keeps those points within this of a_xy_m: A beyond it
        # (with a margin where the field still feels a wall) changes nothing.
        crop = window_around(spec_a, pin.a_xy_m, pin.reach_m + pin.half_size_m + 4 * params.sigma_m)
        values_a, spec_a = crop.crop(values_a), crop.spec
    # The coarsest level needs to span the window, no more: a block wider than it bounds
    # poses outside it, which only loosens the bound.
    offsets = 2 * max(window.half_size_m) / spec_a.resolution_m + 1
    depth = min(params.depth, max(1, math.ceil(math.log2(offsets))))
    pyramid = LikelihoodPyramid.from_occupancy(values_a, spec_a, params.sigma_m, depth)
    # The best pose that A's free space does not contradict: one that puts B's walls
    # where A saw nothing is passed over for the next best (kept with its count).
    search = (
        partial(best_match, points, pyramid, window)
        if pin is None
        else HeadingTable(points, pyramid, window).best
    )
    contradicted: list[tuple[Match, int]] = []
    while True:
        best = search(
            0.0, tuple(m for m, _ in contradicted), params.distinct_m, params.distinct_rad
        )
        if best is None:
            crossing = " without crossing A's free space" if contradicted else ""
            return replace(
                empty,
                reason=f"no pose puts B's surfaces near A's{crossing}",
            )
        placed = transform_points(best.pose, points)
        hits = _free_space_hits(values_a, spec_a, pyramid, placed)
        against = int(np.count_nonzero(hits))
        wall_m = longest_wall_m(placed[hits], 1.5 * params.point_spacing_m)
        if (
            against <= params.max_contradiction * len(points)
            and wall_m < params.max_contradicting_wall_m
        ):
            break
        if len(contradicted) == params.max_alternatives:
            return replace(
                empty,
                pose=best.pose,
                score=best.score,
                contradiction=against / len(points),
                reason=f"the {len(contradicted) + 1} best poses each put more than "
                f"{100 * params.max_contradiction:.0f} % of B's surface points, or a wall of "
                f"{params.max_contradicting_wall_m:g} m, in A's free space",
            )
        contradicted.append((best, against))
    matched = int(np.count_nonzero(pyramid.likelihood_at(placed) >= math.exp(-0.5)))
    decision = MergeDecision(
        True, "", best.pose, best.score, max((m.score for m, _ in contradicted), default=0.0),
        matched, len(points), against / len(points), best.angle_step_rad, best.resolution_m,
    )  # fmt: skip
    if matched < params.min_matched_points:
        return replace(
            decision,
            accepted=False,
            reason=f"too little overlap: {matched} of B's points on A's surfaces, "
            f"{params.min_matched_points} needed",
        )
    # Every other pose that scores nearly as well (or better, and was passed over) must be
    # ruled out by free space: B's walls where A saw nothing, clearly more of them than at
    # the best pose.
    refuting = max(params.refuting_points, params.refuting_share * len(points))
    for other, hits in contradicted:
        if hits - against < refuting:
            return _ambiguous(decision, other, best)
    ruled_out: tuple[Match, ...] = (*(m for m, _ in contradicted), best)
    while len(ruled_out) <= params.max_alternatives:
        other = search(
            params.max_second_ratio * best.score, ruled_out, params.distinct_m,
            params.distinct_rad,
        )  # fmt: skip
        if other is None:
            return replace(decision, pose=refined_pose(points, pyramid, decision))
        decision = replace(decision, second_score=max(decision.second_score, other.score))
        extra = np.count_nonzero(
            _free_space_hits(values_a, spec_a, pyramid, transform_points(other.pose, points))
        )
        if extra - against < refuting:
            return _ambiguous(decision, other, best)
        ruled_out = (*ruled_out, other)
    return replace(
        decision,
        accepted=False,
        reason=f"more than {params.max_alternatives} other poses score nearly as well",
    )


def refined_pose(
    points_m: np.ndarray, pyramid: LikelihoodPyramid, match: MergeDecision
) -> np.ndarray:
    """The match's pose refined off the search's lattice: the pose within a cell and an
    angle step of it where the likelihood field, read between cell centres, is highest.
    The lattice alone leaves up to half a cell and half a step, and a frame merged that
    far off pulls its robots' trajectories after it."""
    assert match.pose is not None
    spec, pad = pyramid.spec, pyramid.pad
    field = pyramid.levels[0]

    def cost(pose: np.ndarray) -> float:
        placed = transform_points(pose, points_m)
        cols = (placed[:, 0] - spec.origin_x_m) / spec.resolution_m - 0.5 + pad
        rows = (placed[:, 1] - spec.origin_y_m) / spec.resolution_m - 0.5 + pad
        return -float(np.mean(ndimage.map_coordinates(field, [rows, cols], order=1)))

    x, y, theta = match.pose
    res, step = match.resolution_m, match.angle_step_rad
    bounds = [(x - res, x + res), (y - res, y + res), (theta - step, theta + step)]
    result = minimize(cost, np.array(match.pose), method="Powell", bounds=bounds)
    return np.asarray(result.x) if result.fun < cost(np.asarray(match.pose)) else match.pose


def _ambiguous(decision: MergeDecision, other: Match, best: Match) -> MergeDecision:
    x, y, theta = other.pose
    return replace(
        decision,
        accepted=False,
        reason=f"ambiguous: the pose ({x:.2f}, {y:.2f}, {theta:.2f}) scores "
        f"{100 * other.score / best.score:.0f} % as well and nothing in A's free space "
        "rules it out",
    )


def merge_maps(
    values_a: np.ndarray,
    spec_a: GridSpec,
    values_b: np.ndarray,
    spec_b: GridSpec,
    pose_b_in_a: np.ndarray,
) -> tuple[np.ndarray, GridSpec]:
    """A's grid grown to hold B placed at ``pose_b_in_a``; unknown takes the other's
    value and a disagreement is occupied."""
    res = spec_a.resolution_m
    left, right, bottom, top = spec_b.extent_m
    corners_b = np.array([[left, bottom], [right, bottom], [left, top], [right, top]])
    placed = transform_points(pose_b_in_a, corners_b)
    lo = np.minimum(placed.min(axis=0), [spec_a.origin_x_m, spec_a.origin_y_m])
    hi = np.maximum(placed.max(axis=0), [spec_a.extent_m[1], spec_a.extent_m[3]])
    # Whole cells of A's lattice, so A's cells are copied, not resampled.
    shift = np.floor((lo - [spec_a.origin_x_m, spec_a.origin_y_m]) / res).astype(int)
    origin = np.array([spec_a.origin_x_m, spec_a.origin_y_m]) + shift * res
    cols, rows = np.ceil((hi - origin) / res).astype(int)
    spec = GridSpec(float(origin[0]), float(origin[1]), res, int(rows), int(cols))
    merged = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    r0, c0 = -shift[1], -shift[0]
    merged[r0 : r0 + spec_a.rows, c0 : c0 + spec_a.cols] = values_a
    return overlay(merged, place_grid(values_b, spec_b, pose_b_in_a, spec)), spec


def on_finer_cells(
    values_a: np.ndarray,
    spec_a: GridSpec,
    values_b: np.ndarray,
    spec_b: GridSpec,
    decision: MergeDecision,
    params: MergeParams | None = None,
) -> MergeDecision:
    """A merge found on coarser cells, searched again on these maps' own cells within a
    coarse cell and angle step of its pose (exactly there), then refined between cells."""
    params = params or MergeParams()
    assert decision.pose is not None
    points = surface_points(values_b, spec_b, params.point_spacing_m)
    pyramid = LikelihoodPyramid.from_occupancy(values_a, spec_a, params.sigma_m, params.depth)
    window = SearchWindow.around(
        decision.pose, points, decision.resolution_m, decision.angle_step_rad
    )
    match = best_match(points, pyramid, window)
    if match is None:
        return decision
    fine = replace(
        decision, pose=match.pose, angle_step_rad=match.angle_step_rad,
        resolution_m=match.resolution_m,
    )  # fmt: skip
    return replace(fine, pose=refined_pose(points, pyramid, fine))


def coarsened(values: np.ndarray, spec: GridSpec, factor: int) -> tuple[np.ndarray, GridSpec]:
    """The map at ``factor`` times its cell size: a coarse cell is occupied if any of its
    cells is, else free if any is, else unknown (walls kept, as a search needs them)."""
    rows, cols = -(-spec.rows // factor), -(-spec.cols // factor)
    padded = np.full((rows * factor, cols * factor), UNKNOWN, dtype=np.int8)
    padded[: spec.rows, : spec.cols] = values
    blocks = padded.reshape(rows, factor, cols, factor)
    coarse = np.where(
        (blocks == OCCUPIED).any(axis=(1, 3)),
        OCCUPIED,
        np.where((blocks == FREE).any(axis=(1, 3)), FREE, UNKNOWN),
    ).astype(np.int8)
    return coarse, replace(spec, resolution_m=spec.resolution_m * factor, rows=rows, cols=cols)


def place_grid(
    values: np.ndarray, spec: GridSpec, pose: np.ndarray, target: GridSpec
) -> np.ndarray:
    """A grid whose frame lies at ``pose`` in ``target``'s frame, read at each of
    ``target``'s cell centres (the nearest cell; UNKNOWN off the grid).

    Only the target cells over the grid's known part are read: a frame's grid is a
    square twice the building's diagonal wide, and reading it at every cell of the world
    took 33 ms per frame and explored-area sample of an office floor (39 s of a 601 s
    run with unknown starts)."""
    values = np.asarray(values)
    placed = np.full(target.shape, UNKNOWN, dtype=np.int8)
    known = values != UNKNOWN
    known_rows, known_cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    if len(known_rows) == 0:
        return placed
    row_start, row_stop = int(known_rows[0]), int(known_rows[-1]) + 1
    col_start, col_stop = int(known_cols[0]), int(known_cols[-1]) + 1
    # The known part's corners in the target's frame, its box widened by a cell for the
    # rounding of the cell centres on its edge.
    res = spec.resolution_m
    corners = np.array(
        [[spec.origin_x_m + c * res, spec.origin_y_m + r * res]
         for r in (row_start, row_stop) for c in (col_start, col_stop)]
    )  # fmt: skip
    box = (transform_points(pose, corners) - [target.origin_x_m, target.origin_y_m]) / (
        target.resolution_m
    )
    c0, r0 = np.maximum(np.floor(box.min(axis=0)).astype(int) - 1, 0)
    c1, r1 = np.minimum(np.ceil(box.max(axis=0)).astype(int) + 1, [target.cols, target.rows])
    if c0 >= c1 or r0 >= r1:
        return placed
    x_m, y_m, theta = between(np.asarray(pose, dtype=float), np.zeros(3))
    c, s = math.cos(theta), math.sin(theta)
    # The target's cell centres in the grid's frame, row by column (an affine map).
    xs = target.origin_x_m + (np.arange(c0, c1) + 0.5) * target.resolution_m
    ys = target.origin_y_m + (np.arange(r0, r1) + 0.5) * target.resolution_m
    frame_x = c * xs[None, :] - s * ys[:, None] + x_m
    frame_y = s * xs[None, :] + c * ys[:, None] + y_m
    cols = np.floor((frame_x - spec.origin_x_m) / res).astype(np.int64)
    rows = np.floor((frame_y - spec.origin_y_m) / res).astype(np.int64)
    inside = (rows >= row_start) & (rows < row_stop) & (cols >= col_start) & (cols < col_stop)
    block = placed[r0:r1, c0:c1]
    block[inside] = values[rows[inside], cols[inside]]
    return placed


def overlay(values: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Two maps of one grid as one: a cell one left unknown takes the other's value, and
    where they disagree, occupied wins (what a planner must avoid)."""
    merged = np.array(values, dtype=np.int8)
    unknown = merged == UNKNOWN
    merged[unknown] = other[unknown]
    disagree = (~unknown) & (other != UNKNOWN) & (other != merged)
    merged[disagree] = OCCUPIED
    return merged
