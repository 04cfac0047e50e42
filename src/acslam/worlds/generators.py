"""Build the ground-truth world a scenario's ``world`` section describes."""

from __future__ import annotations

from acslam.config import (
    DungeonWorld,
    FloorplanWorld,
    MapFileWorld,
    OsmWorld,
    ThesisWorld,
    VineyardWorld,
    WorldConfig,
)
from acslam.seeding import Stream, rng
from acslam.worlds.dungeon import dungeon_world
from acslam.worlds.floorplan import floorplan_world
from acslam.worlds.osm import osm_world
from acslam.worlds.thesis import thesis_world
from acslam.worlds.vineyard import vineyard_world
from acslam.worlds.world import World


def build_world(cfg: WorldConfig, seed: int) -> World:
    """The world of ``cfg``; random generators draw from the seed's WORLD stream."""
    match cfg:
        case ThesisWorld():
            return thesis_world(cfg)
        case VineyardWorld():
            return vineyard_world(cfg, rng(seed, Stream.WORLD))
        case DungeonWorld():
            return dungeon_world(cfg, rng(seed, Stream.WORLD))
        case OsmWorld():
            return osm_world(cfg)
        case FloorplanWorld():
            return floorplan_world(cfg)
        case MapFileWorld():
            from acslam.worlds.mapio import load_world

            return load_world(cfg.file)
    raise TypeError(f"unknown world config {type(cfg).__name__}")
