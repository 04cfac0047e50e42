"""Travel-graph path lengths against exact Dijkstra on the costmap, per block size.

On the seven IPA floor plans of ``../shared/datasets/floorplans_ipa`` (fully known, robot
radius 0.105 m) and a 100 m x 100 m dungeon: seeded random robot cells and targets, the
exact costmap length of every pair, and the relative error of the travel graph's for each
(block side, end boxes) setting; the allocator's default is 0.2 m and 1
(``FactorGraphParams.travel_block_m``, ``travel_end_blocks``).

Run: ``python benchmarks/travel_graph_accuracy.py [--seed 2] [--starts 12] [--targets 100]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from acslam.config import CostmapConfig, DungeonWorld, FloorplanWorld
from acslam.mapping.costmap import compute_costmap
from acslam.planning.astar import path_costs_to
from acslam.planning.travel_graph import TravelGraphBuilder, travel_costs
from acslam.worlds.floorplan import floorplan_world
from acslam.worlds.generators import build_world
from acslam.worlds.mapio import world_cells
from acslam.worlds.world import World

FLOORPLANS = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "floorplans_ipa"
PLANS = ("office_a", "office_b", "office_c", "office_d", "office_e", "office_f", "lab_ipa")
SETTINGS = ((0.2, 1), (0.2, 2), (0.25, 1), (0.25, 2), (0.3, 2))  # (block side m, end boxes)
RESOLUTION_M = 0.05
ROBOT_RADIUS_M = 0.105


def worlds(seed: int) -> list[tuple[str, World]]:
    if not FLOORPLANS.is_dir():
        raise SystemExit(f"the IPA floor plans are not at {FLOORPLANS}")
    plans = [
        (
            name,
            floorplan_world(FloorplanWorld(generator="floorplan", file=FLOORPLANS / f"{name}.png")),
        )
        for name in PLANS
    ]
    dungeon = DungeonWorld(generator="dungeon", width_m=100.0, height_m=100.0, room_count=100)
    return [*plans, ("dungeon", build_world(dungeon, seed))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--starts", type=int, default=12)
    parser.add_argument("--targets", type=int, default=100)
    args = parser.parse_args()
    errors: dict[tuple[float, int], list[np.ndarray]] = {setting: [] for setting in SETTINGS}
    lengths_m = []
    for name, world in worlds(args.seed):
        costmap = compute_costmap(world_cells(world), world.spec, CostmapConfig(), ROBOT_RADIUS_M)
        rng = np.random.default_rng(args.seed)
        free = np.argwhere(~costmap.lethal)
        starts = free[rng.choice(len(free), args.starts, replace=False)]
        targets = free[rng.choice(len(free), args.targets, replace=False)]
        cost = np.zeros(costmap.lethal.shape)
        exact = np.array(
            [
                path_costs_to(cost, costmap.lethal, tuple(s), targets, RESOLUTION_M, 0.0)
                for s in starts
            ]
        )
        paired = np.isfinite(exact) & (exact > 0)
        lengths_m.append(exact[paired])
        for block_m, end_blocks in SETTINGS:
            graph = TravelGraphBuilder().build(
                cost, costmap.lethal, RESOLUTION_M, 0.0, round(block_m / RESOLUTION_M)
            )
            approx = travel_costs(
                graph, cost, costmap.lethal, starts, targets, RESOLUTION_M, 0.0, end_blocks
            )
            if not np.array_equal(np.isfinite(approx), np.isfinite(exact)):
                raise AssertionError(
                    f"{name}: the travel graph and Dijkstra disagree on reachability"
                )
            errors[(block_m, end_blocks)].append(
                np.abs(approx[paired] - exact[paired]) / exact[paired]
            )
        print(f"{name}: {int(paired.sum())} pairs")
    length_m = np.concatenate(lengths_m)
    print(f"\n{len(length_m)} pairs, seed {args.seed}; relative length error, %")
    print("block m  end  p95   p99   max   max over 4 m  pairs over 5 %")
    for (block_m, end_blocks), parts in errors.items():
        error = np.concatenate(parts)
        print(
            f"{block_m:7.2f}  {end_blocks:3d}  {100 * np.percentile(error, 95):4.2f}  "
            f"{100 * np.percentile(error, 99):4.2f}  {100 * error.max():5.2f}  "
            f"{100 * error[length_m > 4].max():12.2f}  {int((error > 0.05).sum()):14d}"
        )


if __name__ == "__main__":
    main()
