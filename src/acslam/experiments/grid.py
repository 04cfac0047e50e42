"""Experiment grids: which runs a sweep makes, as blocks of cross products.

A grid is a YAML file (or a built-in name) listing blocks; each block is the product
scenarios x robots x planners x allocators x seeds, so "exp5 only with 3 robots" or
"compare allocators only on exp2 and exp3" are separate blocks. Runs that several blocks
share are made once. Every run gets a stable id that names its folder, which is what
lets an interrupted sweep resume.

    name: my-sweep
    max_time_s: 300            # simulated seconds per run [default: the scenario's]
    wall_time_limit_s: 1800    # a run still going after this is stopped as a failure
    blocks:
      - scenarios: [thesis-exp2, my-lab.yaml]   # built-in names or files (relative to this)
        robots: [1, 2, 3]
        planners: [fgp, dwa]
        allocators: [factor-graph, greedy]
        seeds: 3                                 # 3 -> seeds 0, 1, 2; or a list [0, 7]
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
)

from acslam.config import builtin_scenario_names
from acslam.errors import ConfigError, PluginError
from acslam.files import read_yaml
from acslam.pipeline.registry import ALLOCATORS, LOCAL_PLANNERS, Registry
from acslam.scenario import UNKNOWN_STARTS_SUFFIX
from acslam.text import plural

DEFAULT_PLANNER = LOCAL_PLANNERS.default
DEFAULT_ALLOCATOR = ALLOCATORS.default
BUILTIN_GRIDS = ("thesis", "scaling")
THESIS_EXPERIMENTS = tuple(f"thesis-exp{k}" for k in range(1, 6))
SCALING_MAX_TIME_S = 2400.0


def _unique(values: list) -> list:
    """A repeated value would ask for the same runs twice: most likely a typo."""
    if len(set(values)) != len(values):
        raise ValueError("values must not repeat")
    return values


def _registered(registry: Registry) -> AfterValidator:
    def check(name: str) -> str:
        try:
            registry.get(name)
        except PluginError as exc:
            raise ValueError(str(exc)) from None
        return name

    return AfterValidator(check)


PlannerName = Annotated[str, _registered(LOCAL_PLANNERS)]
AllocatorName = Annotated[str, _registered(ALLOCATORS)]


class GridBlock(BaseModel):
    """One cross product of the grid."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = ""
    scenarios: Annotated[list[str], Field(min_length=1)]
    robots: Annotated[list[Annotated[int, Field(ge=1)]], Field(min_length=1)] = [3]
    planners: Annotated[list[PlannerName], Field(min_length=1)] = [DEFAULT_PLANNER]
    allocators: Annotated[list[AllocatorName], Field(min_length=1)] = [DEFAULT_ALLOCATOR]
    seeds: Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=1)] = [0]

    _check_unique = field_validator("scenarios", "robots", "planners", "allocators", "seeds")(
        _unique
    )

    @field_validator("seeds", mode="before")
    @classmethod
    def _seed_count(cls, value: Any) -> Any:
        """``seeds: 3`` means seeds 0, 1, 2."""
        if isinstance(value, int) and not isinstance(value, bool):
            if value < 1:
                raise ValueError("a seed count must be at least 1")
            return list(range(value))
        return value


class ExperimentGrid(BaseModel):
    """A named list of blocks plus the limits every run of the sweep shares."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = "grid"
    max_time_s: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    wall_time_limit_s: Annotated[float, Field(gt=0, allow_inf_nan=False)] | None = None
    blocks: Annotated[list[GridBlock], Field(min_length=1)]


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: everything a worker needs, picklable, with a stable id."""

    run_id: str
    scenario: str
    robots: int
    planner: str
    allocator: str
    seed: int
    max_time_s: float | None
    wall_time_limit_s: float | None
    block: str
    unknown_starts: bool = False

    def key(self) -> dict[str, Any]:
        """What defines the run's result (not the block that asked for it)."""
        key = {
            "scenario": self.scenario,
            "robots": self.robots,
            "planner": self.planner,
            "allocator": self.allocator,
            "seed": self.seed,
            "max_time_s": self.max_time_s,
        }
        return {**key, "unknown_starts": True} if self.unknown_starts else key


def run_id(scenario: str, robots: int, planner: str, allocator: str, seed: int) -> str:
    """``thesis-exp2-3r-fgp-factor-graph-s0``: readable, unique per run, a folder name."""
    stem = Path(scenario).stem if scenario.endswith((".yaml", ".yml")) else scenario
    return f"{stem}-{robots}r-{planner}-{allocator}-s{seed}"


def _field(loc: tuple[Any, ...]) -> str:
    return ".".join(str(item) for item in loc)


def parse_grid(data: Any, source: str) -> ExperimentGrid:
    """Validate loaded YAML; scenario files resolve against the grid file's folder."""
    if not isinstance(data, dict):
        raise ConfigError(source, "", "an experiment grid must be a YAML mapping")
    try:
        grid = ExperimentGrid.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        extra = exc.error_count() - 1
        more = f" (and {plural(extra, 'more problem')})" if extra else ""
        message = first["msg"].removeprefix("Value error, ")
        raise ConfigError(source, _field(first["loc"]), message + more) from None
    names = set(builtin_scenario_names())
    folder = Path(source).parent if Path(source).is_file() else Path.cwd()
    blocks = []
    for b, block in enumerate(grid.blocks):
        scenarios = []
        for s, scenario in enumerate(block.scenarios):
            if scenario in names:
                scenarios.append(scenario)
                continue
            path = Path(scenario) if Path(scenario).is_absolute() else folder / scenario
            if not path.is_file():
                raise ConfigError(
                    source,
                    f"blocks.{b}.scenarios.{s}",
                    f"{scenario!r} is neither a built-in scenario ({', '.join(sorted(names))}) "
                    f"nor a file",
                )
            scenarios.append(str(path.resolve()))
        blocks.append(block.model_copy(update={"scenarios": scenarios}))
    return grid.model_copy(update={"blocks": blocks})


def load_grid_file(path: Path) -> ExperimentGrid:
    return parse_grid(read_yaml(path, "experiment grid file"), str(path))


def builtin_grid(name: str) -> ExperimentGrid:
    """The built-in grids.

    ``thesis``: thesis §5.5, experiments 1-4 with 1, 2 and 3 robots and experiment 5 with
    3 (as the thesis ran them), plus the comparisons on experiments 2 and 3 with 3 robots
    (three and four initial frontiers: one per robot or one spare, where allocation
    matters): the four allocators under the factor-graph planner, and fgp vs dwa under
    the factor-graph allocator. One seed each; ``expand(seeds=K)`` makes K.
    ``scaling``: the 40 m x 40 m dungeon and vineyard with 1, 2, 4 and 8 robots, up to
    ``SCALING_MAX_TIME_S`` simulated seconds: within the scenarios' own 600 s one robot
    explores 73 % of the dungeon and 33 % of the vineyard (~600 m of rows to drive), and
    a run that does not finish gives no exploration time to compare.
    """
    if name == "thesis":
        blocks = [
            GridBlock(name="thesis", scenarios=list(THESIS_EXPERIMENTS[:4]), robots=[1, 2, 3]),
            GridBlock(name="thesis", scenarios=[THESIS_EXPERIMENTS[4]], robots=[3]),
            GridBlock(
                name="allocators",
                scenarios=["thesis-exp2", "thesis-exp3"],
                allocators=["factor-graph", "hungarian", "greedy", "thesis"],
            ),
            GridBlock(
                name="planners", scenarios=["thesis-exp2", "thesis-exp3"], planners=["fgp", "dwa"]
            ),
        ]
    elif name == "scaling":
        blocks = [
            GridBlock(name="scaling", scenarios=["dungeon-40", "vineyard-40"], robots=[1, 2, 4, 8])
        ]
        return ExperimentGrid(name=name, blocks=blocks, max_time_s=SCALING_MAX_TIME_S)
    else:
        raise ConfigError(
            f"<built-in grid {name}>", "", f"unknown grid; built-ins: {', '.join(BUILTIN_GRIDS)}"
        )
    return ExperimentGrid(name=name, blocks=blocks)


def expand(
    grid: ExperimentGrid,
    max_time_s: float | None = None,
    seeds: int | None = None,
    unknown_starts: bool = False,
) -> list[RunSpec]:
    """Every run of the grid once, in block order; ``max_time_s``/``seeds`` override;
    ``unknown_starts``: every run without known relative starts (its id says so)."""
    limit = max_time_s if max_time_s is not None else grid.max_time_s
    specs: dict[str, RunSpec] = {}
    for b, block in enumerate(grid.blocks):
        seed_list = list(range(seeds)) if seeds is not None else block.seeds
        for scenario in block.scenarios:
            for robots in block.robots:
                for planner in block.planners:
                    for allocator in block.allocators:
                        for seed in seed_list:
                            rid = run_id(scenario, robots, planner, allocator, seed)
                            rid += UNKNOWN_STARTS_SUFFIX if unknown_starts else ""
                            spec = RunSpec(
                                rid,
                                scenario,
                                robots,
                                planner,
                                allocator,
                                seed,
                                limit,
                                grid.wall_time_limit_s,
                                block.name or f"block {b}",
                                unknown_starts,
                            )
                            known = specs.get(rid)
                            if known is not None and known.scenario != scenario:
                                raise ConfigError(
                                    grid.name,
                                    f"blocks.{b}.scenarios",
                                    f"{scenario} and {known.scenario} give the same run id "
                                    f"{rid!r}: rename one file",
                                )
                            specs.setdefault(rid, spec)
    return list(specs.values())


def check_cells(grid: ExperimentGrid, source: str, seeds: int | None = None) -> None:
    """Build every scenario of the grid with each of its seeds and its block's largest team
    before the first run, so that a broken scenario file or a team larger than a
    scenario's start poses is one error naming the grid's field (``blocks.0.robots``),
    not a sweep of failed runs. ``seeds`` overrides the blocks' as in :func:`expand`."""
    from acslam.config import load_scenario_config
    from acslam.errors import AcslamError
    from acslam.scenario import build_scenario

    for b, block in enumerate(grid.blocks):
        robots_field = f"blocks.{b}.robots"
        seed_list = list(range(seeds)) if seeds is not None else block.seeds
        for s, scenario in enumerate(block.scenarios):
            try:
                config, label = load_scenario_config(scenario)
                for seed in seed_list:
                    seeded = config.model_copy(update={"seed": seed})
                    build_scenario(seeded, label, max(block.robots), robots_field)
            except ConfigError as exc:
                if exc.field != robots_field:
                    raise ConfigError(source, f"blocks.{b}.scenarios.{s}", str(exc)) from None
                raise ConfigError(source, robots_field, f"{label}: {exc.problem}") from None
            except AcslamError as exc:
                raise ConfigError(source, f"blocks.{b}.scenarios.{s}", str(exc)) from None
