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
    help="Simulated seconds to run [default: the scenario's sim.max_time_s].",
)
def run_command(
    scenario_name: str,
    robots: int | None,
    seed: int | None,
    out_dir: Path | None,
    max_time_s: float | None,
) -> None:
    """Run a scenario in the simulator and write the run folder."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from acslam.runner import run_simulation
    from acslam.scenario import load_scenario

    scenario = load_scenario(scenario_name, robots=robots, seed=seed)
    if out_dir is None:
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        out_dir = Path("runs") / f"{scenario.config.name}-{stamp}"
    duration_s = max_time_s if max_time_s is not None else scenario.config.sim.max_time_s
    _console.print(
        f"[bold]{scenario.config.name}[/]: {scenario.robot_count} robots, "
        f"{duration_s:g} s simulated. The exploration server is not wired in yet: "
        "robots wander by a scan-reactive script."
    )
    with Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s sim"),
        TimeElapsedColumn(),
        console=_console,
        disable=not sys.stderr.isatty() and not sys.stdout.isatty(),
    ) as progress:
        task = progress.add_task("simulating", total=duration_s)
        summary = run_simulation(
            scenario, duration_s, out_dir, on_progress=lambda t: progress.update(task, completed=t)
        )
    table = Table(
        title=f"{scenario.config.name}: {summary.sim_time_s:.0f} s simulated in "
        f"{summary.wall_time_s:.1f} s ({summary.real_time_factor:.0f}x real time)"
    )
    for column in (
        "robot",
        "distance [m]",
        "odometry drift [m]",
        "wall hits",
        "robot hits",
        "scans",
        "landmark obs.",
    ):
        table.add_column(column, justify="right")
    for robot in summary.robots:
        table.add_row(
            robot.name,
            f"{robot.distance_m:.2f}",
            f"{robot.odometry_drift_m:.3f}",
            str(robot.wall_collisions),
            str(robot.robot_collisions),
            str(robot.scans),
            str(robot.landmark_observations),
        )
    _console.print(table)
    _console.print(f"run folder: {out_dir}")


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
