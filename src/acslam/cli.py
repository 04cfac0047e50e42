"""The ``acslam`` command line: argument parsing and the one error boundary.

Every error is one ``acslam: error: ...`` line on stderr (:class:`AcslamGroup`): exit code
2 for a usage error (which adds one line saying where the help is), 1 for bad input (an
:class:`~acslam.errors.AcslamError`). A run stopped by SIGINT or SIGTERM still writes its
results and exits with 130 or 143 (:mod:`acslam.stop`). The work itself lives in the
library modules the commands call.
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from acslam import stop
from acslam.errors import AcslamError, AcslamWarning, DataError
from acslam.eval.relations import DEFAULT_MAX_GAP_S
from acslam.files import output_folder, write_json
from acslam.text import plural

if TYPE_CHECKING:
    from acslam.scenario import Scenario

DEFAULT_SCENARIO = "thesis-exp1"

_console = Console()

scenario_option = click.option(
    "--scenario",
    "scenario_name",
    default=DEFAULT_SCENARIO,
    show_default=True,
    help="Built-in scenario name (see `acslam scenarios`) or a scenario YAML file.",
)
robots_option = click.option(
    "--robots",
    type=click.IntRange(min=1),
    default=None,
    help="Number of robots: the first N start poses of the scenario [default: the scenario's "
    "robots.count, else all its start poses].",
)
seed_option = click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=None,
    help="Seed of the world, the landmarks and every noise stream [default: the scenario's seed].",
)


class PluginChoice(click.Choice):
    """The registered names of a stage kind, looked up when first needed: importing every
    plugin takes over a second, which ``--help`` or an early error need not pay."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.case_sensitive = True

    @property
    def choices(self) -> tuple[str, ...]:  # type: ignore[override]
        from acslam.pipeline.registry import REGISTRIES

        return tuple(REGISTRIES[self.kind].names())


class FiniteFloatRange(click.FloatRange):
    """A FloatRange that refuses NaN and infinity: NaN passes every bound (it compares
    false), and neither is a number of seconds, metres or a rate."""

    name = "float range"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number


def out_option(help_text: str, required: bool = False) -> Callable:
    """--out DIR, the folder a command writes, and --overwrite to reuse one that is not
    empty (:func:`acslam.files.prepare_output_folder`)."""

    def decorate(command: Callable) -> Callable:
        command = click.option(
            "--overwrite",
            is_flag=True,
            help="Empty the --out folder first if it holds files (a folder that is not empty "
            "is refused without it).",
        )(command)
        return click.option(
            "--out",
            "out_dir",
            type=click.Path(file_okay=False, path_type=Path),
            required=required,
            default=None,
            help=help_text,
        )(command)

    return decorate


def max_time_option(help_text: str) -> Callable:
    """--max-time SECONDS; which seconds (simulated, wall-clock, log) the help must say."""
    return click.option(
        "--max-time",
        "max_time_s",
        type=FiniteFloatRange(min=0, min_open=True),
        default=None,
        metavar="SECONDS",
        help=help_text,
    )


def fault_options(needs: str) -> Callable:
    """--drop-rate and --latency-ms: faults a robot agent injects into its sensor messages;
    ``needs`` says what else the command needs for them."""

    def add(command: Callable) -> Callable:
        command = click.option(
            "--latency-ms",
            type=FiniteFloatRange(min=0, max=60000, max_open=True),
            default=0.0,
            show_default=True,
            help=f"Milliseconds of delay added to every sensor message a robot sends ({needs}).",
        )(command)
        return click.option(
            "--drop-rate",
            type=FiniteFloatRange(min=0, max=1, max_open=True),
            default=0.0,
            show_default=True,
            help=f"Fraction of sensor messages a robot drops, seeded ({needs}).",
        )(command)

    return add


class TeamParam(click.ParamType):
    """``--robots`` of the served commands: a count, or the robots' ROS 2 namespaces."""

    name = "N|NS,NS,..."

    def convert(self, value: object, param: click.Parameter | None, ctx: click.Context | None):
        if isinstance(value, (int, list)):
            return value
        text = str(value).strip()
        if text.isdigit() and int(text) >= 1:
            return int(text)
        names = [name.strip().strip("/") for name in text.split(",")]
        if not all(names) or len(set(names)) != len(names):
            self.fail(f"expected a count or distinct namespaces a,b,c; got {text!r}", param, ctx)
        return names


def team_option(command: Callable) -> Callable:
    return click.option(
        "--robots",
        "team",
        type=TeamParam(),
        default=None,
        help="Number of robots (the first N start poses), or with --ros2 their namespaces, "
        "e.g. robot1,robot2 [default: the scenario's robots, namespaces robot_0, ...].",
    )(command)


def ros2_options(command: Callable) -> Callable:
    """--ros2 and how acslam appears on a ROS 2 network."""
    for option in reversed(
        [
            click.option("--ros2", is_flag=True, help="Speak ROS 2 (rmw_zenoh's wire format)."),
            click.option(
                "--distro",
                type=click.Choice(["humble", "jazzy", "kilted", "rolling"]),
                default="jazzy",
                show_default=True,
                help="ROS 2 distribution of the robots: type hashes (Humble has none) and "
                "message types.",
            ),
            click.option(
                "--attachment",
                type=click.Choice(["positional", "legacy"]),
                default="positional",
                show_default=True,
                help="rmw_zenoh's attachment format: positional since rmw_zenoh 0.2.4 "
                "(Jazzy, 2025-04) and 0.1.2 (Humble), legacy key/value before.",
            ),
            click.option(
                "--domain-id",
                type=click.IntRange(0, 232),
                default=0,
                show_default=True,
                help="ROS_DOMAIN_ID of the robots.",
            ),
        ]
    ):
        command = option(command)
    return command


def _ros2(distro: str, attachment: str, domain_id: int, bridge: bool = False):
    from acslam.ros2.node import Ros2Options

    return Ros2Options(domain_id=domain_id, distro=distro, attachment=attachment, bridge=bridge)


def _team(team: int | list[str] | None, ros2: bool) -> tuple[int | None, list[str] | None]:
    """The robot count and, for ROS 2, the namespaces ``--robots`` names."""
    if isinstance(team, list):
        if not ros2:
            raise click.UsageError("--robots: namespaces need --ros2")
        return len(team), team
    return team, None


def _one_line(text: str) -> str:
    return " ".join(text.split("\n"))


@contextmanager
def _warnings_as_lines() -> Iterator[None]:
    """Show acslam's own warnings as one ``acslam: warning:`` line each, without the
    source line Python adds (it is acslam's, not the input's)."""
    previous = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, AcslamWarning):
            click.echo(f"acslam: warning: {_one_line(str(message))}", err=True)
        else:
            previous(message, category, filename, lineno, file, line)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = previous


class AcslamGroup(click.Group):
    """The command group with acslam's one error format, whoever invokes it (the entry
    point, ``python -m acslam.cli``, click's test runner)."""

    def main(  # type: ignore[override]
        self,
        args: list[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        code: Any = 0
        with _warnings_as_lines():
            try:
                # The program is acslam however it is started (``python -m``, a test runner).
                code = super().main(args, "acslam", complete_var, standalone_mode=False, **extra)
            except click.exceptions.NoArgsIsHelpError as exc:
                exc.show()
                code = exc.exit_code
            except click.UsageError as exc:
                click.echo(f"acslam: error: {_one_line(exc.format_message())}", err=True)
                if exc.ctx is not None:
                    click.echo(f"Try '{exc.ctx.command_path} --help' for help.", err=True)
                code = exc.exit_code
            except click.ClickException as exc:
                click.echo(f"acslam: error: {_one_line(exc.format_message())}", err=True)
                code = exc.exit_code
            except click.exceptions.Abort:
                click.echo("acslam: aborted", err=True)
                code = 130
            except AcslamError as exc:
                click.echo(f"acslam: error: {_one_line(str(exc))}", err=True)
                code = 1
        if not standalone_mode:
            return code
        sys.exit(code if isinstance(code, int) else 0)


def _exit_if_stopped(signals: stop.Signals, out_dir: Path) -> None:
    """After a run a signal stopped (its results written): say so and exit 130 / 143."""
    if signals.exit_code is not None:
        click.echo(f"acslam: {signals.reason}: the results so far are in {out_dir}", err=True)
        raise click.exceptions.Exit(signals.exit_code)


@click.group(cls=AcslamGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="acslam")
def cli() -> None:
    """acslam: centralized multi-robot Active Collaborative SLAM on factor graphs."""


@cli.command("scenarios")
def scenarios_command() -> None:
    """List the built-in scenarios, one line each."""
    from acslam.config import builtin_scenario_names, load_scenario_config

    rows = []
    for name in builtin_scenario_names():
        config, _ = load_scenario_config(name)
        robots = config.robots.team_size()
        rows.append((name, config.world.generator, plural(robots, "robot"), config.description))
    widths = [max(len(row[k]) for row in rows) for k in range(3)]
    for row in rows:
        click.echo(
            "  ".join(cell.ljust(width) for cell, width in zip(row, widths, strict=False))
            + "  "
            + row[3]
        )


@cli.command("map")
@scenario_option
@robots_option
@seed_option
@out_option("Folder for map.yaml, map.pgm (ROS map_server format) and map.png.", required=True)
def map_command(
    scenario_name: str, robots: int | None, seed: int | None, out_dir: Path, overwrite: bool
) -> None:
    """Build a scenario's ground-truth world and write it as a map."""
    from acslam.eval.figures import plot_world
    from acslam.scenario import load_scenario
    from acslam.worlds.mapio import save_map, world_cells

    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    world = scenario.world
    with output_folder(out_dir, overwrite=overwrite):
        yaml_path, _ = save_map(out_dir / "map", world_cells(world), world.spec)
        plot_world(world, scenario.starts, scenario.landmarks, out_dir / "map.png")
    click.echo(
        f"{world.name}: {world.spec.cols} x {world.spec.rows} cells at "
        f"{world.spec.resolution_m:g} m, free {world.free_area_m2():.1f} m², "
        f"{plural(scenario.robot_count, 'start pose')}, "
        f"{plural(len(scenario.landmarks), 'landmark')} -> "
        f"{yaml_path.parent}"
    )


@cli.command("merge", short_help="Find where map B lies in map A; write the merged map.")
@click.argument("map_a", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("map_b", type=click.Path(dir_okay=False, path_type=Path))
@out_option(
    "Folder for merge.json, merge.png and, when the merge is accepted, map.yaml + map.pgm.",
    required=True,
)
def merge_command(map_a: Path, map_b: Path, out_dir: Path, overwrite: bool) -> None:
    """Find where MAP_B lies in MAP_A (ROS map_server YAML files, same resolution) with no
    guess: every position and heading is searched, and the best pose is accepted only
    with real overlap, no walls of B in A's free space, and no rival pose that fits as
    well. Writes the decision to merge.json and both maps with the merged one to
    merge.png; exits with status 1 when no merge is accepted."""
    import numpy as np

    from acslam.errors import ConfigError
    from acslam.eval.slam_figures import plot_map_panels
    from acslam.geometry import transform_points
    from acslam.mapping.merge import MergeParams, find_merge, merge_maps
    from acslam.worlds.mapio import load_map, save_map

    values_a, spec_a = load_map(map_a)
    values_b, spec_b = load_map(map_b)
    if not math.isclose(spec_a.resolution_m, spec_b.resolution_m, rel_tol=1e-9):
        raise ConfigError(
            map_b,
            "resolution",
            f"{spec_b.resolution_m:g} m differs from {map_a}'s {spec_a.resolution_m:g} m: "
            "resample one map first",
        )
    decision = find_merge(values_a, spec_a, values_b, spec_b)
    with output_folder(out_dir, overwrite=overwrite):
        summary = {"map_a": str(map_a), "map_b": str(map_b), **decision.as_dict()}
        write_json(out_dir / "merge.json", summary)
        panels = [
            (values_a, spec_a, [], f"A: {map_a.name}"),
            (values_b, spec_b, [], f"B: {map_b.name}"),
        ]
        if decision.accepted:
            merged, spec = merge_maps(values_a, spec_a, values_b, spec_b, decision.pose)
            save_map(out_dir / "map", merged, spec)
            left, right, bottom, top = spec_b.extent_m
            corners = [[left, bottom], [right, bottom], [right, top], [left, top], [left, bottom]]
            outline = transform_points(decision.pose, np.array(corners))
            panels.append((merged, spec, [outline], "merged (B's grid outlined)"))
        plot_map_panels(out_dir / "merge.png", panels)
    if not decision.accepted:
        click.echo(f"no merge: {decision.reason} -> {out_dir}")
        sys.exit(1)
    x, y, theta = decision.pose
    rivals = (
        f"the best rival, ruled out by A's free space, scores "
        f"{100 * decision.second_score / decision.score:.0f} % as well"
        if decision.second_score > 0
        else f"no other pose scores within {100 * MergeParams().max_second_ratio:.0f} % of it"
    )
    click.echo(
        f"B lies in A at x {x:.3f} m, y {y:.3f} m, heading {theta:.4f} rad (to within a "
        f"{decision.resolution_m:g} m cell and {decision.angle_step_rad:.4f} rad); "
        f"{decision.matched_points} of B's {decision.points} surface points on A's walls; "
        f"{rivals} -> {out_dir}"
    )


@cli.command("run", short_help="Explore a scenario with the server in the loop.")
@scenario_option
@robots_option
@seed_option
@click.option(
    "--planner",
    type=PluginChoice("local_planner"),
    default=None,
    help="Local planner [default: the scenario's algorithms.local_planner, fgp].",
)
@click.option(
    "--allocator",
    type=PluginChoice("allocator"),
    default=None,
    help="Frontier allocator [default: the scenario's algorithms.allocator, factor-graph].",
)
@out_option("Run folder [default: runs/<scenario>-<time>].")
@max_time_option(
    "Simulated seconds before the run stops; with --distributed the robots simulate in real "
    "time, so these are wall-clock seconds too [default: the scenario's sim.max_time_s]."
)
@click.option(
    "--distributed",
    is_flag=True,
    help="Server here and one `acslam robot` process per robot over Zenoh on loopback, "
    "in real time.",
)
@fault_options("needs --distributed; not with --ros2")
@ros2_options
@click.option(
    "--viz",
    type=click.Choice(["none", "rerun"]),
    default="none",
    show_default=True,
    help="Log map, costmap, scans, trajectories, frontiers, goals and paths to Rerun (needs "
    "the viz extra: pip install 'acslam[viz]').",
)
@click.option(
    "--viz-out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the Rerun recording to this .rrd file (needs --viz rerun) [default: spawn a "
    "live viewer].",
)
@click.option(
    "--patrol-s",
    type=click.FloatRange(min=0.0),
    default=None,
    help="Once explored, drive loops through the map for this long before the run ends: "
    "metrics.json's `patrol` compares each stage's p95 between the loops' first and last "
    "tenth [default: the scenario's algorithms.server.patrol_s, 0].",
)
@click.option(
    "--unknown-starts",
    is_flag=True,
    help="The server is not told where the robots start: each robot begins in its own "
    "frame, and the frames merge where their maps are found to overlap (sets "
    "robots.relative_starts: unknown; metrics.json's `unknown_starts` judges every merge, "
    "merges/ shows each).",
)
@click.option(
    "--record",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Record the run as a ROS 2 bag (rosbag2, MCAP storage) in this .mcap file: per "
    "robot scan, odom, landmarks, tf, tf_static, cmd_vel and ground_truth, and /map (not with "
    "--distributed).",
)
def run_command(
    scenario_name: str,
    robots: int | None,
    seed: int | None,
    planner: str | None,
    allocator: str | None,
    out_dir: Path | None,
    overwrite: bool,
    max_time_s: float | None,
    distributed: bool,
    drop_rate: float,
    latency_ms: float,
    ros2: bool,
    distro: str,
    attachment: str,
    domain_id: int,
    viz: str,
    viz_out: Path | None,
    patrol_s: float | None,
    unknown_starts: bool,
    record: Path | None,
) -> None:
    """Explore a scenario with the full server in the loop and write the run folder."""
    from acslam.runner import RunHooks, run_exploration
    from acslam.scenario import load_scenario

    if (drop_rate or latency_ms) and not distributed:
        raise click.UsageError("--drop-rate and --latency-ms need --distributed")
    if ros2 and not distributed:
        raise click.UsageError("--ros2 needs --distributed")
    if ros2 and (drop_rate or latency_ms):
        raise click.UsageError("--drop-rate and --latency-ms are not available with --ros2")
    if viz_out is not None and viz == "none":
        raise click.UsageError("--viz-out needs --viz rerun")
    if record is not None and distributed:
        raise click.UsageError("--record records in-process runs only (not --distributed)")
    if record is not None and record.suffix != ".mcap":
        raise click.UsageError("--record: the bag is written as an .mcap file")
    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    scenario = scenario.with_algorithms(local_planner=planner, allocator=allocator)
    if patrol_s is not None:
        scenario = scenario.with_patrol(patrol_s)
    if unknown_starts:
        scenario = scenario.with_unknown_starts()
    if (viz != "none" or record is not None) and scenario.config.robots.relative_starts == (
        "unknown"
    ):
        raise click.UsageError(
            "--viz and --record show the team in one frame: not with unknown starts"
        )
    if out_dir is None:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out_dir = Path("runs") / f"{scenario.config.name}-{stamp}"
    limit_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    with (
        stop.on_signals() as signals,
        output_folder(out_dir, overwrite=overwrite),
        _progress(scenario.config.name, limit_s) as show,
        _visualizer(viz, viz_out, scenario) as on_step,
        _recorder(record, scenario) as bag,
    ):
        hooks = RunHooks(
            on_progress=show,
            on_step=_each_step(on_step, None if bag is None else bag.on_step),
            on_finish=None if bag is None else bag.on_finish,
        )
        if distributed:
            from acslam.distributed.launch import run_distributed
            from acslam.distributed.robot_node import RobotOptions
            from acslam.transport.zenoh_link import FaultInjection

            options = RobotOptions(faults=FaultInjection(drop_rate, latency_ms / 1000))
            metrics = run_distributed(
                scenario, scenario_name, out_dir, limit_s, robot_options=options,
                ros2=_ros2(distro, attachment, domain_id) if ros2 else None, hooks=hooks,
            )  # fmt: skip
        else:
            metrics = run_exploration(scenario, out_dir, limit_s, hooks=hooks)
    print_run_summary(metrics)
    _console.print(
        f"run folder: {out_dir}  (report: {out_dir / 'report.html'})", markup=False, soft_wrap=True
    )
    _exit_if_stopped(signals, out_dir)


@contextmanager
def _visualizer(viz: str, viz_out: Path | None, scenario: Scenario) -> Iterator:
    """The per-step logging callback ``--viz`` asks for (None for ``none``)."""
    if viz == "none":
        yield None
        return
    from acslam.viz.rerun_log import RerunLogger

    logger = RerunLogger(scenario, viz_out)
    try:
        yield logger.log_step
    finally:
        logger.close()


@contextmanager
def _recorder(record: Path | None, scenario: Scenario) -> Iterator:
    """The bag recorder ``--record`` asks for (None without it); a run that stops on an
    exception still leaves what it recorded."""
    if record is None:
        yield None
        return
    from acslam.ros2.record import BagRecorder

    recorder = BagRecorder(record, scenario)
    try:
        yield recorder
    finally:
        recorder.close()


def _each_step(*hooks: Callable | None) -> Callable | None:
    """One step hook that calls each given one in turn (None if none is given)."""
    given = [hook for hook in hooks if hook is not None]
    if len(given) <= 1:
        return given[0] if given else None

    def each(snapshot, messages) -> None:
        for hook in given:
            hook(snapshot, messages)

    return each


def _percent(fraction: float | None, digits: int = 1) -> str:
    """A fraction as a percentage; a rate with nothing to count (null) as a dash."""
    return "—" if fraction is None else f"{100 * fraction:.{digits}f} %"


PLAIN_PROGRESS_SHARE = 0.1
"""Piped or redirected, a run prints a line each time it passes another tenth of its limit,"""
PLAIN_PROGRESS_WALL_S = 30.0
"""... or after this many wall-clock seconds without a line, whichever comes first."""


@contextmanager
def _progress(name: str, limit_s: float) -> Iterator[Callable]:
    """The run's progress hook (snapshot, simulated s, mapped m²): a live bar on a
    terminal; elsewhere (a log file, a pipe) a live bar would leave one stale line, so
    plain lines instead."""
    if _console.is_terminal:
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        with Progress(
            TextColumn("{task.description}", markup=False),
            BarColumn(),
            TextColumn(
                "{task.fields[sim]:>6.1f} s simulated  {task.fields[explored]:>6.1f} m² mapped"
                "  {task.fields[frontiers]:>6} frontier cells",
                markup=False,
            ),
            TimeElapsedColumn(),
            console=_console,
        ) as progress:
            task = progress.add_task(name, total=limit_s, sim=0.0, explored=0.0, frontiers=0)

            def show(snapshot, time_s: float, explored_m2: float) -> None:
                progress.update(
                    task,
                    completed=time_s,
                    sim=time_s,
                    explored=explored_m2,
                    frontiers=len(snapshot.frontier_cells),
                )

            yield show
        return
    started_s = last_line_s = time.monotonic()
    last_share = 0

    def show_line(snapshot, time_s: float, explored_m2: float) -> None:
        nonlocal last_line_s, last_share
        now_s = time.monotonic()
        share = math.floor(time_s / (PLAIN_PROGRESS_SHARE * limit_s))
        if share <= last_share and now_s - last_line_s < PLAIN_PROGRESS_WALL_S:
            return
        last_line_s, last_share = now_s, max(share, last_share)
        click.echo(
            f"{name}: {time_s:.1f} of {limit_s:g} s simulated "
            f"({min(100.0, 100 * time_s / limit_s):.0f} %), "
            f"{explored_m2:.1f} m² mapped, "
            f"{plural(len(snapshot.frontier_cells), 'frontier cell')}, "
            # Unknown starts: how many frames are still apart.
            + (f"{plural(len(snapshot.frames), 'frame')}, " if snapshot.frames else "")
            + f"{now_s - started_s:.0f} s elapsed"
        )

    yield show_line


def print_run_summary(metrics: dict) -> None:
    """The run's outcome and its main numbers, each with its unit."""
    status = "completed" if metrics["completed"] else f"NOT completed: {metrics['reason']}"
    _console.print(
        f"{metrics['scenario']}, {plural(metrics['robots'], 'robot')}: {status} in "
        f"{metrics['sim_time_s']:.1f} s simulated ({metrics['real_time_factor']:.1f}x real time)",
        markup=False,
        soft_wrap=True,
    )
    per_robot_s = metrics["timing"]["per_robot_s"]
    unfinished = None in per_robot_s.values()
    table = Table(caption="time —: still exploring when the run stopped" if unfinished else None)
    for column in (
        "robot",
        "time [s]",
        "RMSE [m]",
        "final error [m]",
        "yaw RMSE [rad]",
        "area [m²]",
    ):
        # Square brackets are rich markup: unescaped, "[s]" would vanish as a style tag.
        table.add_column(escape(column), justify="right")
    for name, time_s in per_robot_s.items():
        loc = metrics["localization"].get(name)  # none without ground truth (real robots)
        errors = (
            ["—"] * 3
            if loc is None
            else [f"{loc[key]:.3f}" for key in ("rmse_m", "final_dist_m", "rmse_yaw_rad")]
        )
        time_text = "—" if time_s is None else f"{time_s:.1f}"
        area_m2 = metrics["coverage"][name]["area_m2"]
        table.add_row(escape(name), time_text, *errors, f"{area_m2:.1f}")
    _console.print(table)
    if metrics.get("team_alignment"):
        from acslam.eval.report import team_alignment_text

        _console.print(team_alignment_text(metrics["team_alignment"]), markup=False, soft_wrap=True)
    unknown = metrics.get("unknown_starts")
    if unknown:
        from acslam.eval.report import merge_text

        for merge in unknown["merges"]:
            _console.print(merge_text(merge), markup=False, soft_wrap=True)
        if not unknown["all_merged"]:
            frames = ", ".join(unknown["frames_at_end"])
            _console.print(f"frames not merged by the end: {frames}", markup=False)
    online = metrics["online_localization"]
    if online:
        worst = max(online, key=lambda name: online[name]["max_m"])
        _console.print(
            "The pose each robot was driven by, at every step before later corrections: "
            f"position RMSE {max(m['rmse_m'] for m in online.values()):.3f} m at worst, "
            f"largest error {online[worst]['max_m']:.3f} m ({worst}).",
            markup=False,
            soft_wrap=True,
        )
    mapping, safety, coverage = metrics["mapping"], metrics["safety"], metrics["coverage"]
    travelled_m = metrics["waste"]["travelled_m"]
    aligned = (
        ""
        if mapping.get("aligned_accuracy") is None
        else f" ({_percent(mapping['aligned_accuracy'])} aligned)"
    )
    _console.print(
        f"explored {_percent(coverage['explored_fraction_of_reachable'], 2)} of the "
        f"{coverage['reachable_area_m2']:.1f} m² of reachable free area (the team map holds "
        f"{coverage['mapped_area_m2']:.1f} m², walls included; "
        f"{_percent(metrics['waste']['overlap_ratio'])} of the robots' mapped area was seen "
        f"by more than one); the robots drove {metrics['waste']['travelled_total_m']:.1f} m "
        f"({', '.join(f'{name} {m:.1f}' for name, m in travelled_m.items())}); map accuracy "
        f"{_percent(mapping['accuracy'])}{aligned}, TPR {_percent(mapping['tpr'])}; collisions: "
        f"{safety['obstacle_collisions']} with walls, {safety['robot_collisions']} between "
        f"robots; {plural(safety['stuck_events'], 'stuck event')}; server cycle "
        f"{metrics['server_cycle_ms']['mean']:.1f} ms mean, "
        f"{metrics['server_cycle_ms']['p95']:.1f} ms p95",
        markup=False,
        soft_wrap=True,
    )
    patrol = metrics.get("patrol")
    if patrol and "cycle" in patrol["stages"]:
        cycle = patrol["stages"]["cycle"]
        _console.print(
            f"patrol from {patrol['start_s']:.0f} s to {patrol['end_s']:.0f} s: server cycle "
            f"p95 {cycle['first_tenth_p95_ms']:.1f} ms over its first tenth, "
            f"{cycle['last_tenth_p95_ms']:.1f} ms over its last ({cycle['growth']:.2f}x)",
            markup=False,
            soft_wrap=True,
        )


@cli.command("report", short_help="Rebuild a run's report.html and figures/ from its files.")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
def report_command(run_dir: Path) -> None:
    """Rebuild report.html and figures/ of a finished run without re-running it."""
    from acslam.eval.report import rebuild_report

    click.echo(f"report: {rebuild_report(run_dir)}")


@cli.group("slam", short_help="Replay real recordings through SLAM and score them.")
def slam_group() -> None:
    """Replay real recordings through the localizer stage and score them."""


def algorithms_option(preset: str | None) -> Callable:
    """--algorithms FILE|PRESET: the replay's stages and parameters instead of its default
    (a built-in ``preset``, or with None the simulated robots')."""
    default = (
        f"the built-in {preset} preset, src/acslam/replay/presets/{preset}.yaml"
        if preset
        else "the simulated robots' algorithms, a scenario's defaults"
    )
    return click.option(
        "--algorithms",
        "algorithms_file",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help="An algorithms YAML (the `algorithms` section of a scenario) or a built-in "
        f"preset's name (carmen, mrclam) [default: {default}].",
    )


def _algorithms(name_or_path: Path | None):
    from acslam.replay import algorithms_config

    return None if name_or_path is None else algorithms_config(name_or_path)


@slam_group.command("mrclam", short_help="Localize the 5 robots of a UTIAS MRCLAM dataset.")
@click.argument("path", type=click.Path(file_okay=False, path_type=Path))
@out_option("Folder for metrics.json, TUM trajectories and trajectories.png.", required=True)
@click.option(
    "--known-association",
    is_flag=True,
    help="Reference mode: use the barcodes as landmark identities instead of PDA.",
)
@max_time_option(
    "Seconds of the recording's own clock: use only its first SECONDS [default: all of it]."
)
@click.option(
    "--inter-robot/--no-inter-robot",
    default=True,
    show_default=True,
    help="Add a factor between two robots' poses when one sees the other's barcode.",
)
@click.option(
    "--unknown-starts",
    is_flag=True,
    help="No start poses: each robot starts in its own frame, and the frames merge where "
    "the robots' sightings of each other place them; scored after the one rigid motion "
    "that lays the team on the truth (metrics.json's `unknown_starts` judges every merge).",
)
@algorithms_option("mrclam")
def slam_mrclam_command(
    path: Path,
    out_dir: Path,
    overwrite: bool,
    known_association: bool,
    max_time_s: float | None,
    inter_robot: bool,
    unknown_starts: bool,
    algorithms_file: Path | None,
) -> None:
    """Localize the 5 robots of a UTIAS MRCLAM dataset in one factor graph and score it.

    Landmark identities reach the association only with --known-association; start poses
    come from the first ground-truth sample (none with --unknown-starts), nothing else
    reads ground truth.
    """
    from acslam.replay.mrclam import run_mrclam

    if unknown_starts and not inter_robot:
        raise click.UsageError(
            "--unknown-starts merges the robots' frames by their sightings of each other: "
            "not with --no-inter-robot"
        )
    algorithms = _algorithms(algorithms_file)
    with output_folder(out_dir, overwrite=overwrite):
        metrics = run_mrclam(
            path,
            out_dir,
            known_association=known_association,
            max_time_s=max_time_s,
            algorithms=algorithms,
            inter_robot=inter_robot,
            unknown_starts=unknown_starts,
        )
    overall = metrics["overall"]
    if unknown_starts:
        merges = metrics["unknown_starts"]
        for merge in merges["merges"]:
            error = merge["error_at_robots"]
            click.echo(
                f"{merge['merged_at_s']:.0f} s: robots {merge['robots']} merged into "
                f"{merge['into']} frame ({error['translation_m']:.3f} m off at the robots"
                f"{', FALSE' if merge['false'] else ''})"
            )
        if merges["unmerged_robots"]:
            click.echo(f"never merged: robots {merges['unmerged_robots']}")
    aligned = " after team alignment" if unknown_starts else ""
    click.echo(
        f"position RMSE{aligned} {overall['slam']['rmse_m']:.3f} m (dead reckoning "
        f"{overall['dead_reckoning']['rmse_m']:.3f} m), landmark RMSE "
        f"{metrics['landmarks']['rmse_m']:.3f} m, association precision "
        f"{metrics['association']['pairwise_precision']:.3f} -> {out_dir / 'metrics.json'}"
    )


@slam_group.command("carmen", short_help="Replay a CARMEN laser log through SLAM and mapping.")
@click.argument("log", type=click.Path(dir_okay=False, path_type=Path))
@out_option(
    "Folder for trajectory.tum, map.yaml/.pgm/.png, odometry_vs_slam.png, metrics.json.",
    required=True,
)
@algorithms_option("carmen")
def slam_carmen_command(
    log: Path, out_dir: Path, overwrite: bool, algorithms_file: Path | None
) -> None:
    """Replay a CARMEN laser log (ODOM + FLASER, plain, .bz2 or .gz) through SLAM and mapping.

    The log plays as the ROS messages `acslam convert carmen` writes of it. Sequential and
    loop-closure scan matching in one iSAM2 graph, then the log-odds map of every scan at
    its optimised pose; one TUM pose per FLASER line (ipc stamps).
    """
    from acslam.replay.carmen import run_carmen

    algorithms = _algorithms(algorithms_file)
    with output_folder(out_dir, overwrite=overwrite):
        metrics = run_carmen(log, out_dir, algorithms=algorithms)
    skipped = metrics["skipped_lines"]["count"]
    click.echo(
        f"{plural(metrics['scans_used'], 'scan')}, {plural(metrics['keyframes'], 'keyframe')}, "
        f"{plural(metrics['loop_closures']['accepted'], 'loop closure')} "
        f"({metrics['loop_closures']['rejected']} rejected), "
        f"{plural(skipped, 'malformed line')} skipped; "
        f"{metrics['log_duration_s']:.0f} s of log in {metrics['wall_time_s']:.0f} s "
        f"({metrics['real_time_factor']:.1f}x real time) -> {out_dir}"
    )


def _namespaces(ctx: click.Context, param: click.Parameter, value: str | None) -> list[str]:
    """--robots ns1,ns2 of `slam rosbag`: distinct namespaces, or the root ("")."""
    if value is None:
        return [""]
    names = [name.strip().strip("/") for name in value.split(",")]
    if not all(names) or len(set(names)) != len(names):
        raise click.BadParameter(f"expected distinct namespaces a,b,c; got {value!r}")
    return names


@slam_group.command("rosbag", short_help="Replay a ROS 1 or ROS 2 bag through SLAM and mapping.")
@click.argument("bag", type=click.Path(path_type=Path))
@out_option(
    "Folder for trajectory.tum (trajectory_<ns>.tum per robot), map.yaml/.pgm/.png, "
    "odometry_vs_slam.png, metrics.json.",
    required=True,
)
@click.option(
    "--robots",
    "namespaces",
    metavar="NS,NS,...",
    callback=_namespaces,
    default=None,
    help="The robots' namespaces, e.g. robot1,robot2: topics /<ns>/scan, /<ns>/odom, "
    "/<ns>/tf_static or /tf_static [default: one robot, topics at the root].",
)
@click.option("--scan-topic", default="scan", show_default=True, help="LaserScan topic.")
@click.option(
    "--odom-topic",
    default="odom",
    show_default=True,
    help="Odometry topic (relative names resolve under each namespace); a robot without "
    "one gets scan-matching odometry.",
)
@click.option(
    "--finish/--no-finish",
    default=True,
    show_default=True,
    help="End the data with a last loop-closure search and settling; without, the estimate "
    "stays where a live run's was when it stopped (a bag of `acslam run --record` then "
    "replays to the run's own trajectories).",
)
@click.option(
    "--unknown-starts",
    is_flag=True,
    help="The robots' relative start poses are unknown: each robot is replayed in its own "
    "frame and the maps are merged where a verified match is found (writes "
    "merge_<robot>.png per merge).",
)
@algorithms_option(None)
def slam_rosbag_command(
    bag: Path,
    out_dir: Path,
    overwrite: bool,
    namespaces: list[str],
    scan_topic: str,
    odom_topic: str,
    finish: bool,
    unknown_starts: bool,
    algorithms_file: Path | None,
) -> None:
    """Replay a ROS bag (rosbag2 .mcap/.db3 or its folder, or ROS 1 .bag) through SLAM and
    mapping.

    Each robot's laser mount comes from tf_static, its start pose from its first odometry
    pose (its odom frame taken as the map frame); one TUM trajectory of the base per robot.
    """
    from acslam.replay.rosbag import run_rosbag
    from acslam.replay.unknown_starts import run_rosbag_unknown_starts
    from acslam.ros2.source import Ros2Topics

    algorithms = _algorithms(algorithms_file)
    topics = Ros2Topics(scan=scan_topic, odom=odom_topic)
    with output_folder(out_dir, overwrite=overwrite):
        if unknown_starts:
            metrics = run_rosbag_unknown_starts(
                bag, out_dir, namespaces=namespaces, topics=topics, algorithms=algorithms,
                finish=finish,
            )  # fmt: skip
        else:
            metrics = run_rosbag(
                bag, out_dir, namespaces=namespaces, topics=topics, algorithms=algorithms,
                finish=finish,
            )  # fmt: skip
    if unknown_starts:
        lines = []
        for name, robot in metrics["robots"].items():
            merge = robot["merge"]
            if merge is None:
                lines.append(f"{name}: the reference frame")
            elif robot["merged"]:
                x, y, theta = merge["pose_b_in_a"]
                lines.append(f"{name}: merged at ({x:.2f} m, {y:.2f} m, {theta:.3f} rad)")
            else:
                lines.append(f"{name}: not merged ({merge['reason']})")
        click.echo(
            "; ".join(lines) + f"; {metrics['log_duration_s']:.0f} s of bag in "
            f"{metrics['wall_time_s']:.0f} s -> {out_dir}"
        )
        return
    robots = ", ".join(
        f"{name}: {plural(robot['scans_used'], 'scan')}, {plural(robot['keyframes'], 'keyframe')}"
        + (" (scan-matching odometry)" if robot["odometry"] == "scan matching" else "")
        for name, robot in metrics["robots"].items()
    )
    click.echo(
        f"{robots}; {plural(metrics['loop_closures']['accepted'], 'loop closure')} "
        f"({metrics['loop_closures']['rejected']} rejected); "
        f"{metrics['log_duration_s']:.0f} s of bag in {metrics['wall_time_s']:.0f} s "
        f"({metrics['real_time_factor']:.1f}x real time) -> {out_dir}"
    )


@cli.group("convert")
def convert_group() -> None:
    """Write recordings as ROS 2 bags (rosbag2 in MCAP storage)."""


@convert_group.command("carmen", short_help="Write a CARMEN log as a rosbag2 file (.mcap).")
@click.argument("log", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("out", type=click.Path(dir_okay=False, path_type=Path))
def convert_carmen_command(log: Path, out: Path) -> None:
    """Write a CARMEN log's odometry and laser as a rosbag2 file OUT (.mcap): /scan
    (LaserScan), /odom (Odometry odom -> base_link), /tf and /tf_static (the laser mount).

    At a FLASER stamp the odometry is the base pose the line's laser pose implies.
    `acslam slam carmen LOG` replays these same messages, so `acslam slam rosbag OUT
    --algorithms carmen` gives its trajectory.
    """
    from acslam.ros2.carmen_bag import convert_carmen

    written = convert_carmen(log, out)
    click.echo(
        f"{plural(written['scans'], 'scan')}, "
        f"{plural(written['odometry_samples'], 'odometry sample')}, "
        f"{written['duration_s']:.0f} s -> {out}"
    )


@cli.group("eval", short_help="Score a trajectory against reference relations.")
def eval_group() -> None:
    """Score trajectories the way published SLAM results are scored."""


@eval_group.command("relations", short_help="Relative pose error on Freiburg relations.")
@click.argument("trajectory", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("relations", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--max-gap-s",
    type=click.FloatRange(min=0.0),
    default=DEFAULT_MAX_GAP_S,
    show_default=True,
    help="How far an estimated pose's stamp may lie from a relation's time.",
)
@click.option(
    "--json",
    "json_out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write the figures to this JSON file.",
)
def eval_relations_command(
    trajectory: Path, relations: Path, max_gap_s: float, json_out: Path | None
) -> None:
    """Score TRAJECTORY (TUM) on RELATIONS (Freiburg: `t1 t2 x y z roll pitch yaw`, the
    pose at t2 in t1's frame), the metric of Kümmerle et al. 2009 that Cartographer's
    Table II reports: mean and std of the translational (m) and rotational (deg) error,
    and the share of relations whose times the trajectory covers."""
    from acslam.eval.relations import read_relations, relation_errors
    from acslam.trajectory import read_tum

    stamps_s, poses = read_tum(trajectory)
    try:
        scores = relation_errors(stamps_s, poses, read_relations(relations), max_gap_s)
    except ValueError as exc:
        raise DataError(trajectory, str(exc)) from None
    if json_out is not None:
        write_json(json_out, scores)
    click.echo(
        f"translation {scores['translation_mean_m']:.4f} ± {scores['translation_std_m']:.4f} m, "
        f"rotation {scores['rotation_mean_deg']:.3f} ± {scores['rotation_std_deg']:.3f} deg "
        f"over {scores['matched']} of {plural(scores['relations'], 'relation')} "
        f"({100 * scores['matched_fraction']:.1f} % matched)"
    )


@eval_group.command("truth-relations", short_help="Write relations from a true trajectory.")
@click.argument("truth", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("out", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--every-s", type=click.FloatRange(min=0.0, min_open=True), default=1.0, show_default=True,
    help="Sample the truth this often; each sample is related to the next.",
)  # fmt: skip
@click.option(
    "--revisit-radius-m", type=click.FloatRange(min=0.0), default=1.0, show_default=True,
    help="Also relate each sample to every earlier one this close ...",
)  # fmt: skip
@click.option(
    "--min-loop-m", type=click.FloatRange(min=0.0), default=5.0, show_default=True,
    help="... that the robot left by at least this much path before it came back.",
)  # fmt: skip
@click.option(
    "--at",
    "at_trajectory",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Relate the truth at this trajectory's stamps (a run's keyframes, "
    "`trajectories/*.estimated.tum`), interpolated, instead of at its own.",
)
def truth_relations_command(
    truth: Path,
    out: Path,
    every_s: float,
    revisit_radius_m: float,
    min_loop_m: float,
    at_trajectory: Path | None,
) -> None:
    """Write OUT, a Freiburg relations file, from TRUTH (TUM), the ground truth of a
    simulated run (`trajectories/*.groundtruth.tum`), to score it with `acslam eval
    relations` like a real log."""
    import numpy as np

    from acslam.eval.metrics import interpolate_poses
    from acslam.eval.relations import relations_from_truth, write_relations
    from acslam.trajectory import read_tum

    stamps_s, poses = read_tum(truth)
    if at_trajectory is not None:
        at_s = read_tum(at_trajectory)[0]
        poses = interpolate_poses(at_s, stamps_s, poses)
        covered = ~np.isnan(poses).any(axis=1)
        if not covered.any():
            raise DataError(at_trajectory, f"no stamp lies within the time of {truth}")
        stamps_s, poses = at_s[covered], poses[covered]
    try:
        made = relations_from_truth(stamps_s, poses, every_s, revisit_radius_m, min_loop_m)
    except ValueError as exc:
        raise DataError(truth, str(exc)) from None
    write_relations(out, made)
    click.echo(f"{plural(len(made), 'relation')} -> {out}")


@cli.group("experiments", short_help="Sweep grids of runs; summarize them like thesis chapter 5.")
def experiments_group() -> None:
    """Sweep grids of runs in parallel and summarize them like thesis chapter 5."""


def _sweep_options(function: click.decorators.FC) -> click.decorators.FC:
    """--out, --workers, --unknown-starts, --executor and --max-time, shared by the
    experiments commands."""
    function = max_time_option(
        "Simulated seconds per run [default: the grid's, else the scenario's]."
    )(function)
    function = click.option(
        "--ray-address",
        default=None,
        help="With --executor ray: a running cluster ('auto', 'ray://HOST:10001') "
        "[default: start a local one].",
    )(function)
    function = click.option(
        "--executor",
        type=click.Choice(["process", "ray"]),
        default="process",
        show_default=True,
        help="process: a pool of local worker processes; ray: Ray tasks on a cluster.",
    )(function)
    function = click.option(
        "--unknown-starts",
        is_flag=True,
        help="Run every scenario without known relative starts (see `acslam run "
        "--unknown-starts`); run ids and scenario names end in -unknown-starts.",
    )(function)
    function = click.option(
        "--workers",
        type=click.IntRange(min=1),
        default=2,
        show_default=True,
        help="Runs in parallel, one process each.",
    )(function)
    return out_option(
        "Sweep folder: runs/<run-id>/ per run, summary.md and summary.html.", required=True
    )(function)


def _sweep_and_summarize(
    specs: list, out_dir: Path, overwrite: bool, options: dict[str, object], title: str
) -> None:
    """Run the sweep into ``out_dir`` (a sweep's own folder resumes) and summarize it; a
    signal stops it after the runs under way have written their results."""
    from acslam.experiments.summary import write_summary
    from acslam.experiments.sweep import SWEEP_FILE, ProcessPoolRunner, sweep_with_progress

    if options["executor"] == "ray":
        from acslam.experiments.ray_executor import RayRunner

        runner = RayRunner(address=options["ray_address"], local_cpus=options["workers"])
    else:
        runner = ProcessPoolRunner(options["workers"])
    with (
        stop.on_signals() as signals,
        output_folder(out_dir, overwrite=overwrite, resumable=SWEEP_FILE),
    ):
        sweep_with_progress(specs, out_dir, runner, _console)
        markdown, page = write_summary(out_dir, title)
    _console.print(f"summary: {markdown}  {page}")
    _exit_if_stopped(signals, out_dir)


@experiments_group.command("thesis", short_help="Reproduce thesis §5.5 and compare the algorithms.")
@_sweep_options
@click.option(
    "--seeds", type=click.IntRange(min=1), default=1, show_default=True, help="Seeds per cell."
)
@click.option(
    "--grid",
    "grid_name",
    type=click.Choice(["thesis", "scaling"]),
    default="thesis",
    show_default=True,
    help="thesis: §5.5 experiments 1-5 plus allocator/planner comparisons; "
    "scaling: 40 m dungeon and vineyard with 1, 2, 4, 8 robots.",
)
def experiments_thesis_command(
    out_dir: Path,
    overwrite: bool,
    max_time_s: float | None,
    seeds: int,
    grid_name: str,
    unknown_starts: bool,
    **executor: object,
) -> None:
    """Reproduce thesis §5.5 (experiments 1-5 with 1-3 robots) and compare algorithms."""
    from acslam.experiments.grid import builtin_grid, check_cells, expand

    grid = builtin_grid(grid_name)
    check_cells(grid, f"<built-in grid {grid_name}>", seeds=seeds)
    specs = expand(grid, max_time_s=max_time_s, seeds=seeds, unknown_starts=unknown_starts)
    title = f"acslam experiments: {grid_name} grid"
    _sweep_and_summarize(specs, out_dir, overwrite, executor, title)


@experiments_group.command("grid", short_help="Run the grid of a YAML file and summarize it.")
@click.argument("grid_file", type=click.Path(dir_okay=False, path_type=Path))
@_sweep_options
def experiments_grid_command(
    grid_file: Path,
    out_dir: Path,
    overwrite: bool,
    max_time_s: float | None,
    unknown_starts: bool,
    **executor: object,
) -> None:
    """Run the grid of a YAML file (scenarios x robots x planners x allocators x seeds)."""
    from acslam.experiments.grid import check_cells, expand, load_grid_file

    grid = load_grid_file(grid_file)
    check_cells(grid, str(grid_file))
    specs = expand(grid, max_time_s=max_time_s, unknown_starts=unknown_starts)
    _sweep_and_summarize(specs, out_dir, overwrite, executor, f"acslam experiments: {grid.name}")


@cli.command("bench", short_help="Time every module against a same-process reference.")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("."),
    show_default=True,
    help="Folder for bench.json.",
)
@click.option("--quick", is_flag=True, help="Smaller problems: about a minute in all.")
def bench_command(out_dir: Path, quick: bool) -> None:
    """Time every module against a reference measured in the same process."""
    from acslam.benchmarks import print_table, run_benchmarks, write_json

    results = run_benchmarks(quick=quick, console=_console)
    print_table(results, _console)
    _console.print(f"bench: {write_json(results, out_dir)}")


@cli.command("serve", short_help="Run the server in wall-clock time for robots over Zenoh.")
@scenario_option
@team_option
@seed_option
@click.option(
    "--listen",
    default=None,
    help="Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (tcp/127.0.0.1:PORT locally); "
    "with --ros2 the server is then the router the robots connect to.",
)
@click.option(
    "--connect",
    multiple=True,
    help="--ros2: the robots' Zenoh router, tcp/HOST:7447 (all robots on one router), or "
    "NS=tcp/HOST:7447 once per robot router. Repeatable.",
)
@out_option("Run folder [default: runs/<scenario>-<time>-serve].")
@max_time_option(
    "Wall-clock seconds before the run stops [default: the scenario's sim.max_time_s]."
)
@click.option(
    "--heartbeat-timeout",
    "heartbeat_timeout_s",
    type=FiniteFloatRange(min=0, min_open=True),
    default=2.0,
    show_default=True,
    help="Seconds without a heartbeat (with --ros2: without odometry) before a robot is "
    "declared lost.",
)
@ros2_options
@click.option(
    "--bridge",
    is_flag=True,
    help="--ros2: robots that stay on DDS, through zenoh-bridge-ros2dds (its keys, no attachment).",
)
@click.option("--scan-topic", default="scan", show_default=True, help="--ros2: LaserScan topic.")
@click.option("--odom-topic", default="odom", show_default=True, help="--ros2: Odometry topic.")
@click.option(
    "--tf-static-topic",
    default="tf_static",
    show_default=True,
    help="--ros2: static transforms (/tf_static for a global one with prefixed frames).",
)
@click.option(
    "--cmd-vel-type",
    type=click.Choice(["auto", "twist", "twist-stamped"]),
    default="auto",
    show_default=True,
    help="--ros2: cmd_vel as geometry_msgs/Twist or TwistStamped (auto: Twist on Humble, "
    "TwistStamped from Jazzy on).",
)
@click.option(
    "--laser-mount",
    type=(FiniteFloatRange(), FiniteFloatRange(), FiniteFloatRange()),
    metavar="X Y YAW",
    default=None,
    help="--ros2: the laser's pose X Y YAW (m, m, rad) in the odometry's base frame, instead "
    "of reading it from tf_static.",
)
@click.option(
    "--global-tf",
    is_flag=True,
    help="--ros2: publish map -> <ns>/odom on /tf instead of map -> odom on /<ns>/tf.",
)
@click.option(
    "--unknown-starts",
    is_flag=True,
    help="The server is not told where the robots start: each robot begins in its own "
    "frame, and the frames merge where the data places them (sets "
    "robots.relative_starts: unknown; with --ros2 an unmerged robot's frame is <ns>/map, "
    "map stays robot 0's, and /tf_static holds every merge).",
)
def serve_command(
    scenario_name: str,
    team: int | list[str] | None,
    seed: int | None,
    listen: str | None,
    connect: tuple[str, ...],
    out_dir: Path | None,
    overwrite: bool,
    max_time_s: float | None,
    heartbeat_timeout_s: float,
    ros2: bool,
    distro: str,
    attachment: str,
    domain_id: int,
    bridge: bool,
    scan_topic: str,
    odom_topic: str,
    tf_static_topic: str,
    cmd_vel_type: str,
    laser_mount: tuple[float, float, float] | None,
    global_tf: bool,
    unknown_starts: bool,
) -> None:
    """Run the server in wall-clock time for robots connecting over Zenoh (acslam's own
    protocol, or with --ros2 ROS 2 robots through rmw_zenoh or the DDS bridge)."""
    from acslam.scenario import load_scenario

    robots, namespaces = _team(team, ros2)
    if not ros2 and (connect or bridge):
        raise click.UsageError("--connect and --bridge need --ros2")
    if not ros2 and listen is None:
        raise click.UsageError("--listen is required (or --ros2 with --connect)")
    if ros2 and listen is None and not connect:
        raise click.UsageError("--ros2 needs --connect (the robots' router) or --listen")
    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    if unknown_starts:
        scenario = scenario.with_unknown_starts()
    if out_dir is None:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out_dir = Path("runs") / f"{scenario.config.name}-{stamp}-serve"
    limit_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    with stop.on_signals() as signals, output_folder(out_dir, overwrite=overwrite):
        if ros2:
            from acslam.ros2.launch import default_namespaces
            from acslam.ros2.serve import Ros2ServeOptions, serve_ros2
            from acslam.ros2.source import Ros2Topics

            namespaces = namespaces or default_namespaces(scenario.robot_count)
            stamped = None if cmd_vel_type == "auto" else cmd_vel_type == "twist-stamped"
            options = Ros2ServeOptions(
                tuple(namespaces),
                _ros2(distro, attachment, domain_id, bridge),
                connect=connect,
                listen=listen,
                topics=Ros2Topics(
                    scan=scan_topic,
                    odom=odom_topic,
                    tf_static=tf_static_topic,
                    cmd_vel_stamped=stamped,
                ),
                global_tf=global_tf,
                laser_mount=laser_mount,
                lost_after_s=heartbeat_timeout_s,
            )
            where = listen or ", ".join(connect)
            click.echo(f"serving ROS 2 robots {', '.join(namespaces)} via {where} -> {out_dir}")
            metrics = serve_ros2(scenario, out_dir, limit_s, options)
        else:
            from acslam.distributed.server_node import ServeOptions, serve

            served = ServeOptions(heartbeat_timeout_s=heartbeat_timeout_s)
            click.echo(f"serving {plural(scenario.robot_count, 'robot')} on {listen} -> {out_dir}")
            metrics = serve(scenario, listen, out_dir, limit_s, options=served)
    print_run_summary(metrics)
    _exit_if_stopped(signals, out_dir)


@cli.command("robot", short_help="Run one simulated robot in real time against a server.")
@scenario_option
@team_option
@seed_option
@click.option("--id", "robot_id", type=click.IntRange(min=0), required=True, help="Robot index.")
@click.option(
    "--connect",
    required=True,
    help="The server's Zenoh endpoint, e.g. tcp/10.0.0.5:7447 (with --ros2: the router's).",
)
@max_time_option(
    "Seconds on the robot's simulated clock, which runs in real time, before it stops "
    "[default: the scenario's sim.max_time_s]."
)
@fault_options("not with --ros2")
@click.option(
    "--command-timeout",
    "command_timeout_s",
    type=FiniteFloatRange(min=0, min_open=True),
    default=0.5,
    show_default=True,
    help="Seconds without a velocity command before the robot stops.",
)
@click.option(
    "--truth-out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write this robot's ground-truth log (.npz) here when it stops.",
)
@ros2_options
def robot_command(
    scenario_name: str,
    team: int | list[str] | None,
    seed: int | None,
    robot_id: int,
    connect: str,
    max_time_s: float | None,
    drop_rate: float,
    latency_ms: float,
    command_timeout_s: float,
    truth_out: Path | None,
    ros2: bool,
    distro: str,
    attachment: str,
    domain_id: int,
) -> None:
    """Run one simulated robot in real time against a server over Zenoh (with --ros2:
    publishing its namespace's scan, odom, tf and landmarks, driven by cmd_vel)."""
    from acslam.distributed.robot_node import RobotOptions
    from acslam.scenario import load_scenario
    from acslam.transport.zenoh_link import FaultInjection

    robots, namespaces = _team(team, ros2)
    if ros2 and (drop_rate or latency_ms):
        raise click.UsageError("--drop-rate and --latency-ms are not available with --ros2")
    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    limit_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    options = RobotOptions(
        faults=FaultInjection(drop_rate, latency_ms / 1000),
        command_timeout_s=command_timeout_s,
        truth_out=truth_out,
    )
    # SIGTERM is how a launcher ends a robot: it stops, writes its ground truth, exits 0.
    with stop.on_signals():
        if ros2:
            from acslam.ros2.launch import default_namespaces
            from acslam.ros2.robot import run_ros2_robot

            reason = run_ros2_robot(
                scenario,
                robot_id,
                namespaces or default_namespaces(scenario.robot_count),
                [connect],
                limit_s,
                options=options,
                ros2=_ros2(distro, attachment, domain_id),
            )
        else:
            from acslam.distributed.robot_node import run_robot

            reason = run_robot(scenario, robot_id, connect, limit_s, options)
    click.echo(f"robot_{robot_id}: stopped ({reason})")


def main() -> None:
    """Entry point: the CLI behind its one error boundary (:class:`AcslamGroup`)."""
    cli.main(prog_name="acslam")


if __name__ == "__main__":
    main()
