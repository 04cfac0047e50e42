"""``acslam bench``: every module timed against a reference measured in the same process.

Groups: server (cycle per module in a short default run), mapping, scan matching (ICP,
and the global branch-and-bound match against the exhaustive search), exploration (EWFD
vs the naive frontier scan, clustering, allocation), planning (A* vs pyastar2d or scipy,
FGP per team size), slam (iSAM2 and the loop-closure candidate search vs graph size),
simulator (real-time factor), team (the server cycle with 1, 3 and 10 robots against
elapsed time). ``--quick`` shrinks every problem so the whole set takes about a minute.
"""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from rich.console import Console
from rich.table import Table

from acslam import files
from acslam.benchmarks.core import Figure

GROUPS = (
    "server",
    "mapping",
    "scan matching",
    "exploration",
    "planning",
    "slam",
    "simulator",
    "team",
)


def _exploration(quick: bool) -> list[Figure]:
    from acslam.benchmarks.perception import (
        bench_allocation,
        bench_frontiers,
        bench_frontiers_large,
        bench_travel_distances,
    )

    figures, final_map = bench_frontiers(quick)
    return (
        figures
        + bench_frontiers_large(quick)
        + bench_allocation(quick, **final_map)
        + bench_travel_distances(quick)
    )


def _runners() -> dict[str, Callable[[bool], list[Figure]]]:
    from acslam.benchmarks import perception, planning, system, team_scaling

    return {
        "server": system.bench_server_cycle,
        "mapping": perception.bench_mapping,
        "scan matching": perception.bench_scan_matching,
        "exploration": _exploration,
        "planning": lambda quick: planning.bench_astar(quick) + planning.bench_fgp(quick),
        "slam": system.bench_isam2,
        "simulator": system.bench_simulator,
        "team": team_scaling.bench_team,
    }


def run_benchmarks(
    quick: bool, console: Console | None = None, groups: tuple[str, ...] = GROUPS
) -> list[Figure]:
    """Run the chosen groups in order; prints each group's wall time to ``console``."""
    runners = _runners()
    figures: list[Figure] = []
    for group in groups:
        started = time.perf_counter()
        figures += runners[group](quick)
        if console is not None:
            console.print(f"[dim]{group}: {time.perf_counter() - started:.1f} s[/]")
    return figures


def print_table(figures: list[Figure], console: Console) -> None:
    table = Table(title="acslam bench: value, reference measured in the same process, ratio")
    for column in ("group", "benchmark", "value", "reference", "ratio", "note"):
        table.add_column(column, justify="right" if column in ("value", "ratio") else "left")
    for f in figures:
        table.add_row(
            f.group,
            f.name,
            f"{f.value:.3g} {f.unit}",
            f"{f.reference}: {f.reference_value:.3g} {f.unit}",
            f"{f.ratio:.3g}",
            f.note,
        )
    console.print(table)


def write_json(figures: list[Figure], out_dir: Path) -> Path:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "bench.json"
    data = {
        "machine": {"python": platform.python_version(), "processor": platform.processor()},
        "figures": [asdict(f) | {"ratio": f.ratio} for f in figures],
    }
    files.write_json(path, data, indent=1)
    return path


def main_for(*groups: str) -> None:
    """Entry point of the scripts in ``benchmarks/``: the full-size figures of some groups."""
    console = Console()
    print_table(run_benchmarks(quick=False, console=console, groups=groups), console)
