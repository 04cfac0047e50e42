"""The ``acslam`` command line: argument parsing and the one error boundary.

Every :class:`~acslam.errors.AcslamError` becomes one line on stderr and exit code 1;
the work itself lives in the library modules the commands call.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

import click
from rich.console import Console
from rich.table import Table

from acslam.errors import AcslamError

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
    help="Number of robots: the first N start poses of the scenario.",
)
seed_option = click.option(
    "--seed", type=click.IntRange(min=0), default=None, help="Override the scenario seed."
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


def out_option(help_text: str, required: bool = False) -> Callable:
    """--out DIR, the folder a command writes."""
    return click.option(
        "--out",
        "out_dir",
        type=click.Path(file_okay=False, path_type=Path),
        required=required,
        default=None,
        help=help_text,
    )


def max_time_option(help_text: str) -> Callable:
    """--max-time SECONDS; what the seconds are (simulated, wall, log) is the help's."""
    return click.option(
        "--max-time",
        "max_time_s",
        type=click.FloatRange(min=0, min_open=True),
        default=None,
        help=help_text,
    )


def fault_options(command: Callable) -> Callable:
    """--drop-rate and --latency-ms: faults a robot agent injects into its sensor messages."""
    command = click.option(
        "--latency-ms",
        type=click.FloatRange(min=0, max=60000, max_open=True),
        default=0.0,
        show_default=True,
        help="Delay added to every sensor message a robot sends.",
    )(command)
    return click.option(
        "--drop-rate",
        type=click.FloatRange(min=0, max=1, max_open=True),
        default=0.0,
        show_default=True,
        help="Fraction of sensor messages a robot drops (seeded).",
    )(command)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
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
        robots = config.robots.count or len(config.robots.starts or []) or 1
        rows.append((name, config.world.generator, f"{robots} robots", config.description))
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
def map_command(scenario_name: str, robots: int | None, seed: int | None, out_dir: Path) -> None:
    """Build a scenario's ground-truth world and write it as a map."""
    from acslam.eval.figures import plot_world
    from acslam.scenario import load_scenario
    from acslam.worlds.mapio import save_map, world_cells

    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    world = scenario.world
    yaml_path, _ = save_map(out_dir / "map", world_cells(world), world.spec)
    plot_world(world, scenario.starts, scenario.landmarks, out_dir / "map.png")
    click.echo(
        f"{world.name}: {world.spec.cols} x {world.spec.rows} cells at "
        f"{world.spec.resolution_m:g} m, free {world.free_area_m2():.1f} m^2, "
        f"{scenario.robot_count} start poses, {len(scenario.landmarks)} landmarks -> "
        f"{yaml_path.parent}"
    )


@cli.command("run")
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
@max_time_option("Simulated seconds before the run stops [default: the scenario's sim.max_time_s].")
@click.option(
    "--distributed",
    is_flag=True,
    help="Server here and one `acslam robot` process per robot over Zenoh on loopback, "
    "in real time.",
)
@fault_options
@click.option(
    "--viz",
    type=click.Choice(["none", "rerun"]),
    default="none",
    show_default=True,
    help="Log map, costmap, scans, trajectories, frontiers, goals and paths to Rerun.",
)
@click.option(
    "--viz-out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the Rerun recording to this .rrd file [default: spawn a live viewer].",
)
def run_command(
    scenario_name: str,
    robots: int | None,
    seed: int | None,
    planner: str | None,
    allocator: str | None,
    out_dir: Path | None,
    max_time_s: float | None,
    distributed: bool,
    drop_rate: float,
    latency_ms: float,
    viz: str,
    viz_out: Path | None,
) -> None:
    """Explore a scenario with the full server in the loop and write the run folder."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from acslam.runner import RunHooks, run_exploration
    from acslam.scenario import load_scenario

    if (drop_rate or latency_ms) and not distributed:
        raise click.UsageError("--drop-rate and --latency-ms need --distributed")
    if viz_out is not None and viz == "none":
        raise click.UsageError("--viz-out needs --viz rerun")
    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    scenario = scenario.with_algorithms(local_planner=planner, allocator=allocator)
    if out_dir is None:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out_dir = Path("runs") / f"{scenario.config.name}-{stamp}"
    limit_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    reachable_m2 = scenario.reachable_area_m2
    with Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        TextColumn(
            "{task.fields[sim]:>6.1f} s sim  explored {task.fields[explored]:>5.1f} m²"
            "  frontiers {task.fields[frontiers]:>5}"
        ),
        TimeElapsedColumn(),
        console=_console,
    ) as progress:
        task = progress.add_task(
            scenario.config.name, total=limit_s, sim=0.0, explored=0.0, frontiers=0
        )

        def show(snapshot, time_s: float, explored_m2: float) -> None:
            progress.update(
                task,
                completed=time_s,
                sim=time_s,
                explored=explored_m2,
                frontiers=len(snapshot.frontier_cells),
            )

        with _visualizer(viz, viz_out, scenario) as on_step:
            hooks = RunHooks(on_progress=show, on_step=on_step)
            if distributed:
                from acslam.distributed.launch import run_distributed
                from acslam.distributed.robot_node import RobotOptions
                from acslam.transport.zenoh_link import FaultInjection

                options = RobotOptions(faults=FaultInjection(drop_rate, latency_ms / 1000))
                metrics = run_distributed(
                    scenario, scenario_name, out_dir, limit_s,
                    robot_options=options, hooks=hooks,
                )  # fmt: skip
            else:
                metrics = run_exploration(scenario, out_dir, limit_s, hooks=hooks)
    _print_summary(metrics, reachable_m2)
    _console.print(f"run folder: {out_dir}  (report: {out_dir / 'report.html'})")


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


def _print_summary(metrics: dict, reachable_m2: float) -> None:
    status = "completed" if metrics["completed"] else f"NOT completed: {metrics['reason']}"
    table = Table(
        title=f"{metrics['scenario']}, {metrics['robots']} robots: {status} in "
        f"{metrics['sim_time_s']:.1f} s simulated ({metrics['real_time_factor']:.1f}x real time)"
    )
    for column in (
        "robot",
        "time [s]",
        "RMSE [m]",
        "final error [m]",
        "yaw RMSE [rad]",
        "area [m²]",
    ):
        table.add_column(column, justify="right")
    for name, loc in metrics["localization"].items():
        table.add_row(
            name,
            f"{metrics['timing']['per_robot_s'][name]:.1f}",
            f"{loc['rmse_m']:.3f}",
            f"{loc['final_dist_m']:.3f}",
            f"{loc['rmse_yaw_rad']:.3f}",
            f"{metrics['coverage'][name]['area_m2']:.1f}",
        )
    _console.print(table)
    mapping, safety, coverage = metrics["mapping"], metrics["safety"], metrics["coverage"]
    _console.print(
        f"explored {100 * coverage['explored_fraction_of_reachable']:.1f} % of the "
        f"{reachable_m2:.1f} m² reachable; map accuracy {100 * mapping['accuracy']:.1f} %, "
        f"TPR {100 * mapping['tpr']:.1f} %; collisions: {safety['obstacle_collisions']} wall, "
        f"{safety['robot_collisions']} robot; stuck events {safety['stuck_events']}; "
        f"server cycle {metrics['server_cycle_ms']['mean']:.1f} ms mean, "
        f"{metrics['server_cycle_ms']['p95']:.1f} ms p95"
    )


@cli.command("report")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
def report_command(run_dir: Path) -> None:
    """Rebuild report.html and figures/ of a finished run without re-running it."""
    from acslam.eval.report import rebuild_report

    click.echo(f"report: {rebuild_report(run_dir)}")


@cli.group("slam")
def slam_group() -> None:
    """Replay real recordings through the localizer stage and score them."""


def algorithms_option(preset: str) -> Callable:
    """--algorithms FILE: the replay's stages and parameters instead of a built-in preset."""
    return click.option(
        "--algorithms",
        "algorithms_file",
        type=click.Path(dir_okay=False, path_type=Path),
        default=None,
        help=f"An algorithms YAML (the `algorithms` section of a scenario) [default: the "
        f"built-in {preset} preset, src/acslam/replay/presets/{preset}.yaml].",
    )


def _algorithms(path: Path | None):
    from acslam.config import load_algorithms

    return None if path is None else load_algorithms(path)


@slam_group.command("mrclam")
@click.argument("path", type=click.Path(file_okay=False, path_type=Path))
@out_option("Folder for metrics.json, TUM trajectories and trajectories.png.", required=True)
@click.option(
    "--known-association",
    is_flag=True,
    help="Reference mode: use the barcodes as landmark identities instead of PDA.",
)
@max_time_option("Use only the first SECONDS of the recording [default: all of it].")
@click.option(
    "--inter-robot/--no-inter-robot",
    default=True,
    show_default=True,
    help="Add a factor between two robots' poses when one sees the other's barcode.",
)
@algorithms_option("mrclam")
def slam_mrclam_command(
    path: Path,
    out_dir: Path,
    known_association: bool,
    max_time_s: float | None,
    inter_robot: bool,
    algorithms_file: Path | None,
) -> None:
    """Localize the 5 robots of a UTIAS MRCLAM dataset in one factor graph and score it.

    Landmark identities reach the association only with --known-association; start poses
    come from the first ground-truth sample, nothing else reads ground truth.
    """
    from acslam.replay.mrclam import run_mrclam

    metrics = run_mrclam(
        path,
        out_dir,
        known_association=known_association,
        max_time_s=max_time_s,
        algorithms=_algorithms(algorithms_file),
        inter_robot=inter_robot,
    )
    overall = metrics["overall"]
    click.echo(
        f"position RMSE {overall['slam']['rmse_m']:.3f} m (dead reckoning "
        f"{overall['dead_reckoning']['rmse_m']:.3f} m), landmark RMSE "
        f"{metrics['landmarks']['rmse_m']:.3f} m, association precision "
        f"{metrics['association']['pairwise_precision']:.3f} -> {out_dir / 'metrics.json'}"
    )


@slam_group.command("carmen")
@click.argument("log", type=click.Path(dir_okay=False, path_type=Path))
@out_option(
    "Folder for trajectory.tum, map.yaml/.pgm/.png, odometry_vs_slam.png, metrics.json.",
    required=True,
)
@algorithms_option("carmen")
def slam_carmen_command(log: Path, out_dir: Path, algorithms_file: Path | None) -> None:
    """Replay a CARMEN laser log (ODOM + FLASER, plain, .bz2 or .gz) through SLAM and mapping.

    Sequential and loop-closure scan matching in one iSAM2 graph, then the log-odds map
    of every scan at its optimised pose; one TUM pose per FLASER line (ipc stamps).
    """
    from acslam.replay.carmen import run_carmen

    metrics = run_carmen(log, out_dir, algorithms=_algorithms(algorithms_file))
    skipped = metrics["skipped_lines"]["count"]
    click.echo(
        f"{metrics['scans_used']} scans, {metrics['keyframes']} keyframes, "
        f"{metrics['loop_closures']['accepted']} loop closures "
        f"({metrics['loop_closures']['rejected']} rejected), {skipped} malformed lines skipped; "
        f"{metrics['log_duration_s']:.0f} s of log in {metrics['wall_time_s']:.0f} s "
        f"({metrics['real_time_factor']:.1f}x real time) -> {out_dir}"
    )


@cli.group("experiments")
def experiments_group() -> None:
    """Sweep grids of runs in parallel and summarize them like thesis chapter 5."""


def _sweep_options(function: click.decorators.FC) -> click.decorators.FC:
    """--out, --workers, --executor and --max-time, shared by the experiments commands."""
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
    specs: list, out_dir: Path, options: dict[str, object], title: str
) -> None:
    from acslam.experiments.summary import write_summary
    from acslam.experiments.sweep import ProcessPoolRunner, sweep_with_progress

    if options["executor"] == "ray":
        from acslam.experiments.ray_executor import RayRunner

        runner = RayRunner(address=options["ray_address"], local_cpus=options["workers"])
    else:
        runner = ProcessPoolRunner(options["workers"])
    sweep_with_progress(specs, out_dir, runner, _console)
    markdown, page = write_summary(out_dir, title)
    _console.print(f"summary: {markdown}  {page}")


@experiments_group.command("thesis")
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
    out_dir: Path, max_time_s: float | None, seeds: int, grid_name: str, **executor: object
) -> None:
    """Reproduce thesis §5.5 (experiments 1-5 with 1-3 robots) and compare algorithms."""
    from acslam.experiments.grid import builtin_grid, expand

    specs = expand(builtin_grid(grid_name), max_time_s=max_time_s, seeds=seeds)
    _sweep_and_summarize(specs, out_dir, executor, f"acslam experiments: {grid_name} grid")


@experiments_group.command("grid")
@click.argument("grid_file", type=click.Path(dir_okay=False, path_type=Path))
@_sweep_options
def experiments_grid_command(
    grid_file: Path, out_dir: Path, max_time_s: float | None, **executor: object
) -> None:
    """Run the grid of a YAML file (scenarios x robots x planners x allocators x seeds)."""
    from acslam.experiments.grid import expand, load_grid_file

    grid = load_grid_file(grid_file)
    specs = expand(grid, max_time_s=max_time_s)
    _sweep_and_summarize(specs, out_dir, executor, f"acslam experiments: {grid.name}")


@cli.command("bench")
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


@cli.command("serve")
@scenario_option
@robots_option
@seed_option
@click.option(
    "--listen",
    required=True,
    help="Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (tcp/127.0.0.1:PORT locally).",
)
@out_option("Run folder [default: runs/<scenario>-<time>-serve].")
@max_time_option(
    "Wall-clock seconds before the run stops [default: the scenario's sim.max_time_s]."
)
@click.option(
    "--heartbeat-timeout",
    "heartbeat_timeout_s",
    type=click.FloatRange(min=0, min_open=True),
    default=2.0,
    show_default=True,
    help="Seconds without a heartbeat before a robot is declared lost.",
)
def serve_command(
    scenario_name: str,
    robots: int | None,
    seed: int | None,
    listen: str,
    out_dir: Path | None,
    max_time_s: float | None,
    heartbeat_timeout_s: float,
) -> None:
    """Run the server in wall-clock time for robots connecting over Zenoh."""
    from acslam.distributed.server_node import ServeOptions, serve
    from acslam.scenario import load_scenario

    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    if out_dir is None:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out_dir = Path("runs") / f"{scenario.config.name}-{stamp}-serve"
    limit_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    options = ServeOptions(heartbeat_timeout_s=heartbeat_timeout_s)
    click.echo(f"serving {scenario.robot_count} robots on {listen} -> {out_dir}")
    metrics = serve(scenario, listen, out_dir, limit_s, options=options)
    _print_summary(metrics, scenario.reachable_area_m2)


@cli.command("robot")
@scenario_option
@robots_option
@seed_option
@click.option("--id", "robot_id", type=click.IntRange(min=0), required=True, help="Robot index.")
@click.option(
    "--connect", required=True, help="The server's Zenoh endpoint, e.g. tcp/10.0.0.5:7447."
)
@max_time_option("Seconds before the robot stops [default: the scenario's sim.max_time_s].")
@fault_options
@click.option(
    "--command-timeout",
    "command_timeout_s",
    type=click.FloatRange(min=0, min_open=True),
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
def robot_command(
    scenario_name: str,
    robots: int | None,
    seed: int | None,
    robot_id: int,
    connect: str,
    max_time_s: float | None,
    drop_rate: float,
    latency_ms: float,
    command_timeout_s: float,
    truth_out: Path | None,
) -> None:
    """Run one simulated robot in real time against a server over Zenoh."""
    from acslam.distributed.robot_node import RobotOptions, run_robot
    from acslam.scenario import load_scenario
    from acslam.transport.zenoh_link import FaultInjection

    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    limit_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    options = RobotOptions(
        faults=FaultInjection(drop_rate, latency_ms / 1000),
        command_timeout_s=command_timeout_s,
        truth_out=truth_out,
    )
    reason = run_robot(scenario, robot_id, connect, limit_s, options)
    click.echo(f"robot_{robot_id}: stopped ({reason})")


def main() -> None:
    """Entry point: run the CLI behind the single AcslamError boundary."""
    try:
        cli.main(standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("acslam: aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except AcslamError as exc:
        click.echo(f"acslam: error: {exc}", err=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
