"""Frontier allocation as a discrete factor graph (thesis §4.6, eqs. 4.37-4.42).

One variable x_i per robot over the clusters it can reach. Eq. 4.37 maximises

    prod_i phi_i(x_i) * prod_{i<j} psi_ij(x_i, x_j),
    phi_i = exp(-alpha d(r_i, x_i) + beta s(x_i))                              (4.40)
    psi_ij = e^lambda if x_i = x_j else e                                     (4.41)

so, as a MAP problem in log form (what this module computes and reports as
``log_value``):

    x* = argmax_x  J(x),  J(x) = sum_i [-alpha d_i(x_i) + beta s(x_i)]
                                 + sum_{i<j} (lambda if x_i = x_j else 1)
       = argmin_x  sum_i [alpha d_i(x_i) - beta s(x_i)]
                   + (1 - lambda) * #{i<j : x_i = x_j}   (+ a constant).

Eq. 4.42 subtracts psi_ij itself rather than log psi_ij = lambda or 1; the correct
negative log-likelihood (4.39) is the line above: with lambda << 1 a shared cluster costs
1 - lambda > 0, the robots are pushed apart. "Strong" conflict penalty means lambda << 0.

Exact solution: GTSAM ``DiscreteFactorGraph.optimize()`` (max-product variable
elimination). The pairwise factors connect every pair of robots, so its cost grows as the
product of the domain sizes. Two exact reductions keep it small: unreachable clusters are
not in a robot's domain, and when lambda <= 1 each robot keeps only its N best clusters
by unary value (N = robots): if robot i's choice were outside its N best, one of those
is chosen by none of the other N - 1 robots, and moving i there raises its unary and
adds no conflict, so an optimum never needs the others. Beyond
``exact_max_joint_assignments`` the approximate solver is used: several starts (each
robot's best; sequential greedy) improved by single-robot best responses and joint
best responses of robot pairs until no move helps (a 2-opt local search).

A robot with no reachable cluster is idle. Sharing is allowed (penalised), so every other
robot gets a cluster: no "none" value is needed in the factor graph.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import gtsam
import numpy as np
from scipy.optimize import linear_sum_assignment

from acslam.errors import NoPathError
from acslam.exploration.clustering import FrontierCluster
from acslam.exploration.params import TravelParams, UtilityParams
from acslam.mapping.costmap import Costmap
from acslam.pipeline.stages import Cells, Clusters, Goals
from acslam.planning.astar import path_costs_to, snap_to_free
from acslam.planning.travel_graph import TravelGraphBuilder, travel_costs

_MIN_LOG_FACTOR = -600.0
"""Factor values below e^-600 are stored as e^-600 (doubles underflow near e^-745)."""


@dataclass(frozen=True)
class Allocation:
    """Which cluster each robot goes to.

    ``allocator``: the plugin's name. ``solver``: "exact", "approximate", "hungarian" or
    "greedy". ``cluster_of_robot[i]``: index into the clusters list, or ``None`` (idle: no
    cluster reachable). ``distances_m``: (robots, clusters) d used, inf where unreachable.
    """

    allocator: str
    solver: str
    cluster_of_robot: tuple[int | None, ...]
    distances_m: np.ndarray

    def status(self, robot: int) -> Literal["assigned", "idle"]:
        return "idle" if self.cluster_of_robot[robot] is None else "assigned"


# --------------------------------------------------------------------------- objective


def unary_log_factors(
    distances_m: np.ndarray, utilities: np.ndarray, alpha: float, beta: float
) -> np.ndarray:
    """(robots, clusters) log phi = -alpha d + beta s; -inf where d is inf (unreachable)."""
    d = np.asarray(distances_m, dtype=float)
    with np.errstate(invalid="ignore"):
        unary = -alpha * d + beta * np.asarray(utilities, dtype=float)[None, :]
    unary[~np.isfinite(d)] = -np.inf
    return unary


def log_objective(
    assignment: list[int | None] | tuple[int | None, ...],
    unary: np.ndarray,
    conflict_lambda: float,
) -> float:
    """J(x) over the assigned robots (module docstring); idle robots contribute nothing."""
    chosen = [(i, k) for i, k in enumerate(assignment) if k is not None]
    value = sum(float(unary[i, k]) for i, k in chosen)
    for (_, a), (_, b) in itertools.combinations(chosen, 2):
        value += conflict_lambda if a == b else 1.0
    return value


# --------------------------------------------------------------------------- solvers


def _domains(unary: np.ndarray, conflict_lambda: float) -> list[np.ndarray]:
    """Per robot, the clusters worth considering (reachable; N best when lambda <= 1)."""
    robots = unary.shape[0]
    domains = []
    for row in unary:
        reachable = np.flatnonzero(np.isfinite(row))
        if conflict_lambda <= 1.0 and len(reachable) > robots:
            best = np.argsort(-row[reachable], kind="stable")[:robots]
            reachable = np.sort(reachable[best])
        domains.append(reachable)
    return domains


def joint_assignment_count(unary: np.ndarray, conflict_lambda: float) -> int:
    """Size of the exact problem after the reductions: product of the domain sizes."""
    return math.prod(len(d) for d in _domains(unary, conflict_lambda))


def solve_exact(unary: np.ndarray, conflict_lambda: float) -> list[int]:
    """Max-product MAP on a GTSAM DiscreteFactorGraph; every row needs a finite entry.

    Robots with a single candidate are fixed and folded into the others' unary factors
    (conditioning, exact): GTSAM 4.3 rejects pairwise factors on a cardinality-1 variable
    ("Product factor is 0.0").
    """
    domains = _domains(unary, conflict_lambda)
    log_phi = [unary[i, domain] - unary[i, domain].max() for i, domain in enumerate(domains)]
    fixed = [i for i, domain in enumerate(domains) if len(domain) == 1]
    free = [i for i, domain in enumerate(domains) if len(domain) > 1]
    for i in free:
        for j in fixed:
            log_phi[i] = log_phi[i] + np.where(domains[i] == domains[j][0], conflict_lambda - 1, 0)
    result = [int(domain[0]) for domain in domains]
    if not free:
        return result
    graph = gtsam.DiscreteFactorGraph()
    for key, i in enumerate(free):
        table = np.exp(np.maximum(log_phi[i] - log_phi[i].max(), _MIN_LOG_FACTOR))
        graph.add((key, len(domains[i])), table.tolist())
    # psi scaled by 1/e: 1 for different clusters, e^(lambda - 1) for the same one.
    same = math.exp(max(conflict_lambda - 1.0, _MIN_LOG_FACTOR))
    for (ka, i), (kb, j) in itertools.combinations(enumerate(free), 2):
        table = np.where(domains[i][:, None] == domains[j][None, :], same, 1.0)
        if (table != 1.0).any():
            graph.add([(ka, len(domains[i])), (kb, len(domains[j]))], table.ravel().tolist())
    values = graph.optimize()
    for key, i in enumerate(free):
        result[i] = int(domains[i][values[key]])
    return result


def _penalty_counts(assignment: np.ndarray, clusters: int) -> np.ndarray:
    return np.bincount(assignment, minlength=clusters).astype(float)


def _local_repair(unary: np.ndarray, penalty: float, assignment: np.ndarray) -> np.ndarray:
    """Best responses of single robots and of robot pairs until none improves."""
    robots, clusters = unary.shape
    x = assignment.copy()
    same_pair = penalty * np.eye(clusters)
    improved = True
    while improved:
        improved = False
        counts = _penalty_counts(x, clusters)
        for i in range(robots):
            counts[x[i]] -= 1
            score = unary[i] - penalty * counts
            best = int(np.argmax(score))
            if score[best] > score[x[i]] + 1e-12:
                x[i] = best
                improved = True
            counts[x[i]] += 1
        for i, j in itertools.combinations(range(robots), 2):
            counts[x[i]] -= 1
            counts[x[j]] -= 1
            score = (
                (unary[i] - penalty * counts)[:, None]
                + (unary[j] - penalty * counts)[None, :]
                - same_pair
            )
            a, b = np.unravel_index(int(np.argmax(score)), score.shape)
            if score[a, b] > score[x[i], x[j]] + 1e-12:
                x[i], x[j] = int(a), int(b)
                improved = True
            counts[x[i]] += 1
            counts[x[j]] += 1
    return x


def solve_approximate(unary: np.ndarray, conflict_lambda: float) -> list[int]:
    """Greedy starts plus pairwise local repair; every row needs a finite entry."""
    robots, clusters = unary.shape
    penalty = 1.0 - conflict_lambda
    independent = np.argmax(unary, axis=1)
    sequential = np.zeros(robots, dtype=np.int64)
    counts = np.zeros(clusters)
    for i in np.argsort(-unary.max(axis=1), kind="stable"):
        sequential[i] = int(np.argmax(unary[i] - penalty * counts))
        counts[sequential[i]] += 1
    best: list[int] = []
    best_value = -math.inf
    for start in (independent, sequential):
        candidate = _local_repair(unary, penalty, start).tolist()
        value = log_objective(candidate, unary, conflict_lambda)
        if value > best_value:
            best, best_value = candidate, value
    return best


def _fill_with_best(assignment: list[int | None], unary: np.ndarray) -> list[int | None]:
    """Robots left without a cluster take their best reachable one (shared)."""
    return [
        int(np.argmax(unary[i])) if k is None and np.isfinite(unary[i]).any() else k
        for i, k in enumerate(assignment)
    ]


def _hungarian(unary: np.ndarray) -> list[int | None]:
    cost = np.where(np.isfinite(unary), -unary, 1e12)
    rows, cols = linear_sum_assignment(cost)
    assignment: list[int | None] = [None] * unary.shape[0]
    for i, k in zip(rows, cols, strict=True):
        if np.isfinite(unary[i, k]):
            assignment[i] = int(k)
    return _fill_with_best(assignment, unary)


def _greedy_nearest(distances_m: np.ndarray) -> list[int | None]:
    robots, clusters = distances_m.shape
    assignment: list[int | None] = [None] * robots
    taken = np.zeros(clusters, dtype=bool)
    for flat in np.argsort(distances_m, axis=None, kind="stable"):
        i, k = divmod(int(flat), clusters)
        if np.isfinite(distances_m[i, k]) and assignment[i] is None and not taken[k]:
            assignment[i] = k
            taken[k] = True
    return _fill_with_best(assignment, -distances_m)


# --------------------------------------------------------------------------- plugins


def cluster_distances_m(
    robot_cells: np.ndarray,
    clusters: Sequence[FrontierCluster],
    costmap: Costmap,
    params: TravelParams,
    travel_graph: TravelGraphBuilder | None = None,
) -> np.ndarray:
    """(robots, clusters) d: path cost (Dijkstra per robot, or the travel graph for all of
    them), or straight-line metres. ``travel_graph`` keeps the graph of the last costmap
    (an allocator passes its own, so a replan rebuilds only the blocks that changed)."""
    spec = costmap.spec
    cells = np.asarray(robot_cells, dtype=np.int64).reshape(-1, 2)
    targets = np.array([c.target_cell for c in clusters], dtype=np.int64).reshape(-1, 2)
    robots_m = spec.cell_to_world(cells)
    targets_m = spec.cell_to_world(targets)
    euclidean = np.linalg.norm(robots_m[:, None, :] - targets_m[None, :, :], axis=2)
    if params.distance_metric == "euclidean-unchecked":
        return euclidean
    max_snap_cells = math.floor(params.start_snap_m / spec.resolution_m)
    distances = np.full((len(cells), len(targets)), np.inf)
    snapped: list[int] = []
    starts = []
    for i, cell in enumerate(cells):
        try:
            start = snap_to_free(costmap.lethal, (int(cell[0]), int(cell[1])), max_snap_cells)
        except NoPathError:
            continue
        starts.append(start)
        snapped.append(i)
    if params.distance_metric == "travel-graph" and snapped:
        block_cells = max(1, round(params.travel_block_m / spec.resolution_m))
        graph = (travel_graph or TravelGraphBuilder()).build(
            costmap.cost, costmap.lethal, spec.resolution_m, params.path_cost_weight,
            block_cells,
        )  # fmt: skip
        distances[snapped] = travel_costs(
            graph, costmap.cost, costmap.lethal, np.array(starts), targets,
            spec.resolution_m, params.path_cost_weight, params.travel_end_blocks,
        )  # fmt: skip
    else:
        for i, start in zip(snapped, starts, strict=True):
            distances[i] = path_costs_to(
                costmap.cost, costmap.lethal, (int(start[0]), int(start[1])), targets,
                spec.resolution_m, params.path_cost_weight,
            )  # fmt: skip
    if params.distance_metric == "euclidean":
        return np.where(np.isfinite(distances), euclidean, np.inf)
    return distances


def committed_distances_m(
    robot_cells: np.ndarray,
    clusters: Sequence[FrontierCluster],
    costmap: Costmap,
    params: TravelParams,
    current: Sequence[int | None] | None,
    travel_graph: TravelGraphBuilder | None = None,
) -> np.ndarray:
    """d with each robot's current cluster ``params.commitment_m`` closer, so a robot
    switches goals only for a clearly better one (without it, re-allocating every few
    seconds makes robots dither between frontiers)."""
    distances = cluster_distances_m(robot_cells, clusters, costmap, params, travel_graph)
    for robot, cluster in enumerate(current or []):
        if cluster is not None and np.isfinite(distances[robot, cluster]):
            distances[robot, cluster] = max(0.0, distances[robot, cluster] - params.commitment_m)
    return distances


def _unary(
    distances_m: np.ndarray, clusters: Sequence[FrontierCluster], params: UtilityParams
) -> np.ndarray:
    if params.utility == "size":
        utilities = np.array([c.size_cells for c in clusters], dtype=float)
    else:
        utilities = np.array([c.information_gain_cells for c in clusters], dtype=float)
    return unary_log_factors(distances_m, utilities, params.alpha, params.beta)


Solution = tuple[str, list[int | None]]
"""The solver's name and the cluster of each robot (None: idle)."""


class _TravelAllocator:
    """The front end every built-in allocator shares: d with commitment, then a solver."""

    solver = ""  # what Allocation.solver says when there is nothing to solve

    def __init__(self, params: TravelParams) -> None:
        self.params = params
        self._travel_graph = TravelGraphBuilder()

    def allocate(
        self, robot_cells: Cells, clusters: Clusters, costmap: Costmap, current: Goals = None
    ) -> Allocation:
        if not clusters:
            robots = len(np.asarray(robot_cells).reshape(-1, 2))
            return Allocation(
                self.params.name, self.solver, (None,) * robots, np.zeros((robots, 0))
            )
        distances = committed_distances_m(
            robot_cells, clusters, costmap, self.params, current, self._travel_graph
        )
        solver, assignment = self._solve(distances, clusters)
        return Allocation(self.params.name, solver, tuple(assignment), distances)

    def _solve(self, distances_m: np.ndarray, clusters: Clusters) -> Solution:
        raise NotImplementedError


class GreedyAllocator(_TravelAllocator):
    """Nearest robot-cluster pairs first, each cluster once while there are enough."""

    solver = "greedy"

    def _solve(self, distances_m: np.ndarray, clusters: Clusters) -> Solution:
        return self.solver, _greedy_nearest(distances_m)


class HungarianAllocator(_TravelAllocator):
    """The best one-to-one assignment of eq. 4.40's unary values (no pairwise term)."""

    solver = "hungarian"

    def _solve(self, distances_m: np.ndarray, clusters: Clusters) -> Solution:
        return self.solver, _hungarian(_unary(distances_m, clusters, self.params))


class FactorGraphAllocator(_TravelAllocator):
    """Eq. 4.37's MAP on a discrete factor graph: exact, or approximate when large."""

    solver = "exact"

    def _solve(self, distances_m: np.ndarray, clusters: Clusters) -> Solution:
        params = self.params
        unary = _unary(distances_m, clusters, params)
        active = np.flatnonzero(np.isfinite(unary).any(axis=1))
        assignment: list[int | None] = [None] * len(unary)
        solver = "exact"
        if len(active):
            sub = unary[active]
            if joint_assignment_count(sub, params.conflict_lambda) > (
                params.exact_max_joint_assignments
            ):
                solver, chosen = "approximate", solve_approximate(sub, params.conflict_lambda)
            else:
                chosen = solve_exact(sub, params.conflict_lambda)
            for i, k in zip(active, chosen, strict=True):
                assignment[int(i)] = k
        return solver, assignment
