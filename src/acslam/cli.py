"""The ``acslam`` command line: argument parsing and the one error boundary.

Every :class:`~acslam.errors.AcslamError` becomes one line on stderr and exit code 1;
the work itself lives in the library modules the commands call.
"""

from __future__ import annotations

import sys
from datetime import datetime
from pathlib import Path

import click
from rich.console import Console
from rich.table import Table

from acslam.errors import AcslamError

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
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for map.yaml, map.pgm (ROS map_server format) and map.png.",
)
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
    type=click.Choice(["fgp", "dwa"]),
    default=None,
    help="Local planner [default: the scenario's, fgp].",
)
@click.option(
    "--allocator",
    type=click.Choice(["factor-graph", "hungarian", "greedy", "thesis"]),
    default=None,
    help="Frontier allocation method [default: the scenario's, factor-graph].",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Run folder [default: runs/<scenario>-<time>].",
)
@click.option(
    "--max-time",
    "max_time_s",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Simulated seconds before the run stops [default: the scenario's sim.max_time_s].",
)
def run_command(
    scenario_name: str,
    robots: int | None,
    seed: int | None,
    planner: str | None,
    allocator: str | None,
    out_dir: Path | None,
    max_time_s: float | None,
) -> None:
    """Explore a scenario with the full server in the loop and write the run folder."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from acslam.runner import run_exploration
    from acslam.scenario import load_scenario

    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    scenario = scenario.with_algorithms(local_planner=planner, allocation_method=allocator)
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

        def show(status, explored_m2: float) -> None:
            progress.update(
                task,
                completed=status.time_s,
                sim=status.time_s,
                explored=explored_m2,
                frontiers=status.frontier_cells,
            )

        metrics = run_exploration(scenario, out_dir, limit_s, on_progress=show)
    _print_summary(metrics, reachable_m2)
    _console.print(f"run folder: {out_dir}  (report: {out_dir / 'report.html'})")


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
    """Run the SLAM back end alone on real multi-robot datasets."""


@slam_group.command("mrclam")
@click.argument("path", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for metrics.json, TUM trajectories and trajectories.png.",
)
@click.option(
    "--known-association",
    is_flag=True,
    help="Reference mode: use the barcodes as landmark identities instead of PDA.",
)
@click.option(
    "--max-time",
    "max_time_s",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Use only the first SECONDS of the recording [default: all of it].",
)
def slam_mrclam_command(
    path: Path, out_dir: Path, known_association: bool, max_time_s: float | None
) -> None:
    """Localize the 5 robots of a UTIAS MRCLAM dataset in one factor graph and score it.

    Landmark identities reach the association only with --known-association; start poses
    come from the first ground-truth sample, nothing else reads ground truth.
    """
    from acslam.slam.mrclam_eval import run_mrclam

    metrics = run_mrclam(path, out_dir, known_association=known_association, max_time_s=max_time_s)
    overall = metrics["overall"]
    click.echo(
        f"position RMSE {overall['slam']['position_rmse_m']:.3f} m (dead reckoning "
        f"{overall['dead_reckoning']['position_rmse_m']:.3f} m), landmark RMSE "
        f"{metrics['landmarks']['rmse_m']:.3f} m, association precision "
        f"{metrics['association']['pairwise_precision']:.3f} -> {out_dir / 'metrics.json'}"
    )


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
