"""Travel distances on a coarse graph of the costmap: allocation at building scale.

Allocation needs the path length from every robot to every frontier cluster. One Dijkstra
per robot on the costmap visits every cell of the window (~300 ns each): at 0.05 m a
50 m x 50 m window is 1 M cells, a third of a second per robot.

The coarse graph has one node per 8-connected set of free cells inside a block of
``k x k`` cells (with A*'s corner rule), so it is connected exactly where the costmap is:
no wall leaks and no door closes, whatever the block size. A node's representative is its
member cell nearest the block centre. Nodes that touch across a block edge or corner are
joined by the octile distance between their representatives, times the mean step factor
of the two. Both ends of a path are fine: a Dijkstra on the costmap in a box of
``end_blocks`` blocks around the robot gives the cost of reaching each node there (and of
reaching a target inside the box), and one around each target gives the last leg. The
target legs run from the target outwards: with a path cost weight of 0 that is the same
cost, with a weight the cell factors are charged at the other end of each step.

The coarse search is scipy's Dijkstra (C; 3x faster here than a numba one with our heap)
from one extra source node per robot, joined to the nodes of its box at their fine costs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from acslam.planning.astar import path_costs_to, step_factor


@dataclass(frozen=True)
class TravelGraph:
    """The coarse graph of one costmap.

    ``shape``: the costmap's (rows, cols). ``node_cells``: (nodes, 2) representative
    ``[row, col]``. The nodes of block ``b`` (row-major, ``block_cols`` per row) are
    ``block_nodes[b]:block_nodes[b + 1]``. Adjacency as CSR: node ``v``'s neighbours are
    ``neighbours[offsets[v]:offsets[v + 1]]`` at ``costs`` (the unit of A*'s path cost).
    """

    block_cells: int
    block_cols: int
    shape: tuple[int, int]
    node_cells: np.ndarray
    block_nodes: np.ndarray
    offsets: np.ndarray
    neighbours: np.ndarray
    costs: np.ndarray

    @property
    def node_count(self) -> int:
        return len(self.node_cells)


@numba.njit(cache=True)
def _label_blocks(lethal: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per block, 8-connected components of its free cells (corner rule as A*)."""
    rows, cols = lethal.shape
    block_rows = (rows + k - 1) // k
    block_cols = (cols + k - 1) // k
    node_of_cell = np.empty((rows, cols), dtype=np.int32)
    reps = np.empty(block_rows * block_cols + 16, dtype=np.int64)
    block_nodes = np.empty(block_rows * block_cols + 1, dtype=np.int64)
    stack = np.empty(k * k, dtype=np.int64)
    nodes = 0
    for br in range(block_rows):
        r0, r1 = br * k, min(br * k + k, rows)
        for bc in range(block_cols):
            c0, c1 = bc * k, min(bc * k + k, cols)
            block_nodes[br * block_cols + bc] = nodes
            free_cells = 0
            for r in range(r0, r1):
                for c in range(c0, c1):
                    free_cells += not lethal[r, c]
            while nodes + k * k > reps.shape[0]:
                reps = np.concatenate((reps, np.empty_like(reps)))
            if free_cells == (r1 - r0) * (c1 - c0):  # one node: the whole block
                node_of_cell[r0:r1, c0:c1] = nodes
                reps[nodes] = ((r0 + r1 - 1) // 2) * cols + (c0 + c1 - 1) // 2
                nodes += 1
                continue
            node_of_cell[r0:r1, c0:c1] = -1
            if free_cells == 0:
                continue
            for r in range(r0, r1):
                for c in range(c0, c1):
                    if lethal[r, c] or node_of_cell[r, c] >= 0:
                        continue
                    best = r * cols + c
                    best_d2 = (2 * r - r0 - r1 + 1) ** 2 + (2 * c - c0 - c1 + 1) ** 2
                    node_of_cell[r, c] = nodes
                    stack[0] = r * cols + c
                    top = 1
                    while top > 0:
                        top -= 1
                        cell = stack[top]
                        cr = cell // cols
                        cc = cell - cr * cols
                        # squared distance to the block centre, doubled to stay integer
                        d2 = (2 * cr - r0 - r1 + 1) ** 2 + (2 * cc - c0 - c1 + 1) ** 2
                        if d2 < best_d2 or (d2 == best_d2 and cell < best):
                            best, best_d2 = cell, d2
                        for dr in range(-1, 2):
                            for dc in range(-1, 2):
                                nr, nc = cr + dr, cc + dc
                                if nr < r0 or nr >= r1 or nc < c0 or nc >= c1:
                                    continue
                                if lethal[nr, nc] or node_of_cell[nr, nc] >= 0:
                                    continue
                                if dr != 0 and dc != 0 and lethal[nr, cc] and lethal[cr, nc]:
                                    continue
                                node_of_cell[nr, nc] = nodes
                                stack[top] = nr * cols + nc
                                top += 1
                    reps[nodes] = best
                    nodes += 1
    block_nodes[block_rows * block_cols] = nodes
    return node_of_cell, reps[:nodes], block_nodes


@numba.njit(cache=True, inline="always")
def _step_allowed(lethal: np.ndarray, r: int, c: int, nr: int, nc: int) -> bool:
    if lethal[r, c] or lethal[nr, nc]:
        return False
    return not (nr != r and nc != c and lethal[nr, c] and lethal[r, nc])


@numba.njit(cache=True)
def _add_edge(found: np.ndarray, count: int, a: int, b: int) -> int:
    """Append (a, b) to the block pair's list unless it is there already."""
    for i in range(count):
        if found[i, 0] == a and found[i, 1] == b:
            return count
    found[count, 0] = a
    found[count, 1] = b
    return count + 1


@numba.njit(cache=True)
def _block_edges(node_of_cell: np.ndarray, lethal: np.ndarray, k: int) -> np.ndarray:
    """(E, 2) node pairs that touch across a block edge or corner, each pair once."""
    rows, cols = lethal.shape
    block_rows = (rows + k - 1) // k
    block_cols = (cols + k - 1) // k
    edges = np.empty((4 * block_rows * block_cols + 16, 2), dtype=np.int64)
    count = 0
    found = np.empty((3 * k + 2, 2), dtype=np.int64)
    for br in range(block_rows):
        r0, r1 = br * k, min(br * k + k, rows)
        for bc in range(block_cols):
            c0, c1 = bc * k, min(bc * k + k, cols)
            # right neighbour block: steps from column c1 - 1 to c1, rows inside the band
            if c1 < cols:
                n = 0
                for r in range(r0, r1):
                    for nr in range(max(r - 1, r0), min(r + 2, r1)):
                        if _step_allowed(lethal, r, c1 - 1, nr, c1):
                            n = _add_edge(found, n, node_of_cell[r, c1 - 1], node_of_cell[nr, c1])
                while count + n > edges.shape[0]:
                    edges = np.concatenate((edges, np.empty_like(edges)))
                edges[count : count + n] = found[:n]
                count += n
            if r1 < rows:
                n = 0
                # lower neighbour block
                for c in range(c0, c1):
                    for nc in range(max(c - 1, c0), min(c + 2, c1)):
                        if _step_allowed(lethal, r1 - 1, c, r1, nc):
                            n = _add_edge(found, n, node_of_cell[r1 - 1, c], node_of_cell[r1, nc])
                # lower-right and lower-left blocks, through the block's corners
                if c1 < cols and _step_allowed(lethal, r1 - 1, c1 - 1, r1, c1):
                    n = _add_edge(found, n, node_of_cell[r1 - 1, c1 - 1], node_of_cell[r1, c1])
                if c0 > 0 and _step_allowed(lethal, r1 - 1, c0, r1, c0 - 1):
                    n = _add_edge(found, n, node_of_cell[r1 - 1, c0], node_of_cell[r1, c0 - 1])
                while count + n > edges.shape[0]:
                    edges = np.concatenate((edges, np.empty_like(edges)))
                edges[count : count + n] = found[:n]
                count += n
    return edges[:count]


@numba.njit(cache=True)
def _adjacency(
    edges: np.ndarray, edge_cost: np.ndarray, nodes: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Both directions of every edge as CSR (offsets, neighbours, costs)."""
    offsets = np.zeros(nodes + 1, dtype=np.int64)
    for e in range(edges.shape[0]):
        offsets[edges[e, 0] + 1] += 1
        offsets[edges[e, 1] + 1] += 1
    for v in range(nodes):
        offsets[v + 1] += offsets[v]
    fill = offsets[:-1].copy()
    neighbours = np.empty(offsets[nodes], dtype=np.int64)
    costs = np.empty(offsets[nodes], dtype=np.float64)
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        neighbours[fill[a]], costs[fill[a]] = b, edge_cost[e]
        fill[a] += 1
        neighbours[fill[b]], costs[fill[b]] = a, edge_cost[e]
        fill[b] += 1
    return offsets, neighbours, costs


def build_travel_graph(
    cost: np.ndarray,
    lethal: np.ndarray,
    resolution_m: float,
    cost_weight: float,
    block_cells: int,
) -> TravelGraph:
    """The coarse graph of a costmap (module docstring); steps cost as in A*."""
    lethal = np.ascontiguousarray(lethal, dtype=np.bool_)
    node_of_cell, reps, block_nodes = _label_blocks(lethal, block_cells)
    cols = lethal.shape[1]
    node_cells = np.stack([reps // cols, reps % cols], axis=1)
    edges = _block_edges(node_of_cell, lethal, block_cells)
    delta = np.abs(node_cells[edges[:, 0]] - node_cells[edges[:, 1]])
    octile = delta.max(axis=1) + (math.sqrt(2.0) - 1.0) * delta.min(axis=1)
    rep_factor = step_factor(np.asarray(cost).ravel()[reps], cost_weight)
    mean_factor = 0.5 * (rep_factor[edges[:, 0]] + rep_factor[edges[:, 1]])
    offsets, neighbours, costs = _adjacency(edges, resolution_m * octile * mean_factor, len(reps))
    block_cols = (cols + block_cells - 1) // block_cells
    return TravelGraph(
        block_cells, block_cols, lethal.shape, node_cells, block_nodes, offsets, neighbours,
        costs,
    )  # fmt: skip


def _box(
    graph: TravelGraph, cell: np.ndarray, end_blocks: int
) -> tuple[tuple[int, int, int, int], np.ndarray]:
    """The cells ``(r0, r1, c0, c1)`` of the blocks within ``end_blocks`` blocks of the
    cell's block, and the nodes of those blocks."""
    k, block_cols = graph.block_cells, graph.block_cols
    rows, cols = graph.shape
    block_rows = (len(graph.block_nodes) - 1) // block_cols
    br, bc = int(cell[0]) // k, int(cell[1]) // k
    b_r0, b_r1 = max(br - end_blocks, 0), min(br + end_blocks + 1, block_rows)
    b_c0, b_c1 = max(bc - end_blocks, 0), min(bc + end_blocks + 1, block_cols)
    starts = graph.block_nodes[np.arange(b_r0, b_r1) * block_cols + b_c0]
    ends = graph.block_nodes[np.arange(b_r0, b_r1) * block_cols + b_c1]
    nodes = np.concatenate([np.arange(a, b) for a, b in zip(starts, ends, strict=True)])
    return (b_r0 * k, min(b_r1 * k, rows), b_c0 * k, min(b_c1 * k, cols)), nodes


def _fine_costs(
    graph: TravelGraph,
    cost: np.ndarray,
    lethal: np.ndarray,
    cell: np.ndarray,
    to_cells: np.ndarray,
    resolution_m: float,
    cost_weight: float,
    end_blocks: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fine path costs from ``cell`` inside its box: to the box's nodes (ids, costs) and
    to each of ``to_cells`` (inf outside the box)."""
    (r0, r1, c0, c1), nodes = _box(graph, cell, end_blocks)
    inside = (
        (to_cells[:, 0] >= r0) & (to_cells[:, 0] < r1)
        & (to_cells[:, 1] >= c0) & (to_cells[:, 1] < c1)
    )  # fmt: skip
    queries = np.concatenate([graph.node_cells[nodes], to_cells[inside]]) - (r0, c0)
    costs = path_costs_to(
        cost[r0:r1, c0:c1], lethal[r0:r1, c0:c1], (int(cell[0]) - r0, int(cell[1]) - c0),
        queries, resolution_m, cost_weight,
    )  # fmt: skip
    direct = np.full(len(to_cells), np.inf)
    direct[inside] = costs[len(nodes) :]
    return nodes, costs[: len(nodes)], direct


def travel_costs(
    graph: TravelGraph,
    cost: np.ndarray,
    lethal: np.ndarray,
    start_cells: np.ndarray,
    target_cells: np.ndarray,
    resolution_m: float,
    cost_weight: float,
    end_blocks: int,
) -> np.ndarray:
    """(starts, targets) path costs through the graph (inf where unreachable or lethal);
    the fine cost where a target lies in a start's box, if lower."""
    starts = np.asarray(start_cells, dtype=np.int64).reshape(-1, 2)
    targets = np.asarray(target_cells, dtype=np.int64).reshape(-1, 2)
    legs = []
    no_cells = np.zeros((0, 2), dtype=np.int64)
    for cell in targets:
        if lethal[cell[0], cell[1]]:
            legs.append((np.zeros(0, np.int64), np.zeros(0)))
            continue
        nodes, leg, _ = _fine_costs(
            graph, cost, lethal, cell, no_cells, resolution_m, cost_weight, end_blocks
        )
        reached = np.isfinite(leg)
        legs.append((nodes[reached], leg[reached]))
    n = graph.node_count
    offsets, neighbours, costs = [graph.offsets], [graph.neighbours], [graph.costs]
    # The fine cost where a target lies in a start's box, lowered by the graph's below.
    result = np.full((len(starts), len(targets)), np.inf)
    for s, cell in enumerate(starts):
        seeds, seed_costs, result[s] = _fine_costs(
            graph, cost, lethal, cell, targets, resolution_m, cost_weight, end_blocks
        )
        reached = np.isfinite(seed_costs)
        offsets.append(offsets[-1][-1:] + int(reached.sum()))
        neighbours.append(seeds[reached])
        # scipy drops zero-cost edges: the source edges carry 1 more, taken off below.
        costs.append(seed_costs[reached] + 1.0)
    # One source node per start (rows n, n + 1, ...) joined to the nodes of its box.
    sources = csr_matrix(
        (np.concatenate(costs), np.concatenate(neighbours), np.concatenate(offsets)),
        shape=(n + len(starts), n + len(starts)),
    )
    from_starts = dijkstra(sources, directed=True, indices=np.arange(n, n + len(starts))) - 1.0
    for t, (nodes, leg) in enumerate(legs):
        through = (from_starts[:, nodes] + leg[None, :]).min(axis=1, initial=np.inf)
        result[:, t] = np.minimum(result[:, t], through)
    return result
