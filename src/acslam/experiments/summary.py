"""Summary of a sweep: thesis chapter 5's tables over seeds, comparisons, team scaling.

Reads only the run folders (``runs/*/metrics.json``, ``failure.json``) and ``sweep.json``,
so it can be rebuilt at any time, also while a sweep is still going. Every cell shows the
mean +- sample standard deviation (n - 1) over its seeds and how many runs it has.
Exploration times and speed-ups come from completed runs only (a run stopped by its time
limit did not finish exploring); every other figure uses every run that wrote metrics.
A run that failed or did not finish is never dropped: the cell says so, and the run table
at the end gives each run's reason.
"""

from __future__ import annotations

import html
import math
import re
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from acslam.errors import DataError
from acslam.experiments import thesis_data
from acslam.experiments.grid import DEFAULT_ALLOCATOR, DEFAULT_PLANNER
from acslam.experiments.sweep import FAILURE_FILE, SPEC_FILE, SWEEP_FILE
from acslam.files import read_json, write_text
from acslam.text import plural
from acslam.worlds.thesis import thesis_layout

Cell = tuple[str, int, str, str]  # scenario, robots, planner, allocator
THESIS_NAME = {v: k for k, v in thesis_data.THESIS_ROBOT.items()}
_THESIS_SCENARIO = re.compile(r"^thesis-exp([1-5])$")


@dataclass
class RunOutcome:
    """One run as found on disk: its spec, its metrics if written, why it failed if so."""

    run_id: str
    spec: dict
    metrics: dict | None
    failure: str | None

    @property
    def cell(self) -> Cell:
        s = self.spec
        return (s["scenario"], s["robots"], s["planner"], s["allocator"])

    @property
    def completed(self) -> bool:
        return self.metrics is not None and bool(self.metrics["completed"])

    @property
    def status(self) -> str:
        if self.metrics is not None:
            return "completed" if self.completed else "not completed"
        return "failed" if self.failure is not None else "not run yet"

    @property
    def reason(self) -> str:
        if self.metrics is not None:
            return str(self.metrics["reason"])
        return self.failure or "no output yet"


@dataclass(frozen=True)
class Stat:
    """Mean and sample standard deviation (NaN for one value) of ``n`` values."""

    mean: float
    std: float
    n: int


def aggregate(values: Iterable[float | None]) -> Stat | None:
    """Mean +- sample std of the finite values; None if there are none."""
    kept = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    if not kept:
        return None
    mean = sum(kept) / len(kept)
    if len(kept) < 2:
        return Stat(mean, math.nan, 1)
    variance = sum((v - mean) ** 2 for v in kept) / (len(kept) - 1)
    return Stat(mean, math.sqrt(variance), len(kept))


def fmt(stat: Stat | None, digits: int = 1, scale: float = 1.0) -> str:
    if stat is None:
        return "—"
    mean = f"{scale * stat.mean:.{digits}f}"
    return mean if math.isnan(stat.std) else f"{mean} ± {scale * stat.std:.{digits}f}"


def fmt_value(value: float | None, digits: int = 1) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


@dataclass
class Table:
    title: str
    header: list[str]
    rows: list[list[str]]
    note: str = ""


@dataclass
class Section:
    title: str
    intro: str = ""
    tables: list[Table] = field(default_factory=list)


# --------------------------------------------------------------------------- loading


def _read_json(path: Path) -> dict:
    return read_json(path, "sweep file")


def load_runs(out_dir: Path) -> list[RunOutcome]:
    """Every run of the sweep (``sweep.json``), or of the folders found if there is none."""
    out_dir = Path(out_dir)
    runs_dir = out_dir / "runs"
    sweep_path = out_dir / SWEEP_FILE
    if sweep_path.is_file():
        specs = {s["run_id"]: s for s in _read_json(sweep_path)["runs"]}
    else:
        specs = {p.parent.name: _read_json(p) for p in sorted(runs_dir.glob(f"*/{SPEC_FILE}"))}
    if not specs:
        raise DataError(out_dir, "no runs found: not a sweep folder (no sweep.json, no runs/)")
    outcomes = []
    for run_id, spec in specs.items():
        folder = runs_dir / run_id
        metrics_path, failure_path = folder / "metrics.json", folder / FAILURE_FILE
        metrics = _read_json(metrics_path) if metrics_path.is_file() else None
        failure = _read_json(failure_path)["reason"] if failure_path.is_file() else None
        outcomes.append(RunOutcome(run_id, spec, metrics, failure))
    return outcomes


def by_cell(runs: list[RunOutcome]) -> dict[Cell, list[RunOutcome]]:
    cells: dict[Cell, list[RunOutcome]] = defaultdict(list)
    for run in runs:
        cells[run.cell].append(run)
    return dict(cells)


def cell_stat(
    runs: list[RunOutcome], value: Callable[[dict], float | None], completed_only: bool = False
) -> Stat | None:
    """``value(metrics)`` aggregated over the cell's runs with metrics (or completed ones)."""
    return aggregate(
        value(r.metrics)
        for r in runs
        if r.metrics is not None and (r.completed or not completed_only)
    )


def completion(runs: list[RunOutcome]) -> str:
    """``3/3``, or ``1/3 (2 time limit)``: how many completed and why the others did not."""
    done = sum(r.completed for r in runs)
    reasons: dict[str, int] = defaultdict(int)
    for r in runs:
        if not r.completed:
            reasons[r.reason] += 1
    why = "; ".join(f"{n} {reason}" for reason, n in reasons.items())
    return f"{done}/{len(runs)}" + (f" ({why})" if why else "")


def _get(*keys: str) -> Callable[[dict], float | None]:
    def read(metrics: dict) -> float | None:
        value: Any = metrics
        for key in keys:
            if not isinstance(value, dict) or key not in value:
                return None
            value = value[key]
        return None if value is None else float(value)

    return read


# --------------------------------------------------------------------------- sections


def _thesis_cells(
    cells: dict[Cell, list[RunOutcome]], experiment: int
) -> dict[int, list[RunOutcome]]:
    return {
        robots: runs
        for (scenario, robots, planner, allocator), runs in sorted(cells.items())
        if scenario == f"thesis-exp{experiment}"
        and planner == DEFAULT_PLANNER
        and allocator == DEFAULT_ALLOCATOR
    }


def _robot_names(runs: list[RunOutcome]) -> list[str]:
    """Every robot of a cell's largest team, in order."""
    return [f"robot_{i}" for i in range(max(r.spec["robots"] for r in runs))]


def _robot_label(name: str) -> str:
    thesis = THESIS_NAME.get(name)
    return f"{name} ({thesis})" if thesis else name


def _speedup(base: Stat | None, other: Stat | None) -> str:
    if base is None or other is None or other.mean <= 0:
        return "—"
    return f"{base.mean / other.mean:.2f}x"


def timing_table(experiment: int, teams: dict[int, list[RunOutcome]]) -> Table:
    """Thesis Table 5.1 layout: time per robot, total, gap; ours beside the thesis's."""
    header = [""]
    for robots in teams:
        header += [f"ours {experiment}.{robots} [s]", f"thesis {experiment}.{robots} [s]"]
    names = [f"robot_{i}" for i in range(max(teams))]
    totals = {r: cell_stat(runs, _get("timing", "total_s"), True) for r, runs in teams.items()}
    thesis = {r: thesis_data.thesis_timing(experiment, r) or {} for r in teams}
    thesis_one = thesis_data.thesis_timing(experiment, 1)
    rows = []
    for name in names:
        row = [_robot_label(name)]
        for robots, runs in teams.items():
            if int(name.split("_")[1]) >= robots:
                row += ["", ""]
                continue
            ours = cell_stat(runs, _get("timing", "per_robot_s", name), True)
            row += [fmt(ours), fmt_value(thesis[robots].get(name), 3)]
        rows.append(row)
    for label, key in (("Total time", "total_s"), ("Gap time", "gap_s")):
        row = [label]
        for robots, runs in teams.items():
            ours = cell_stat(runs, _get("timing", key), True)
            row += [fmt(ours), fmt_value(thesis[robots].get(key.removesuffix("_s")), 3)]
        rows.append(row)
    row = ["Speed-up over 1 robot"]
    for robots in teams:
        ours = _speedup(totals.get(1), totals[robots])
        theirs = "—"
        if thesis_one and thesis[robots].get("total"):
            theirs = f"{thesis_one['total'] / thesis[robots]['total']:.2f}x"
        row += [ours, theirs]
    rows.append(row)
    rows.append(["Completed runs"] + [x for runs in teams.values() for x in (completion(runs), "")])
    return Table(
        f"Experiment {experiment}: timing evaluation "
        f"(thesis {thesis_data.TIMING_SOURCE[experiment]})",
        header,
        rows,
        "Exploration time per robot: when it was last busy; total: the team's; gap: last "
        "minus first. Completed runs only. Thesis robot names in brackets.",
    )


LOCALIZATION_COLUMNS = (
    ("final dist. [m]", "final_dist_m"),
    ("MAE [m]", "mae_m"),
    ("RMSE [m]", "rmse_m"),
    ("STD [m]", "std_m"),
    ("final yaw [rad]", "final_yaw_rad"),
    ("MAE [rad]", "mae_yaw_rad"),
    ("RMSE [rad]", "rmse_yaw_rad"),
    ("STD [rad]", "std_yaw_rad"),
)


def localization_table(title: str, teams: dict[object, list[RunOutcome]]) -> Table:
    """Thesis Table 5.2 layout: position and heading errors per robot."""
    rows = []
    for label, runs in teams.items():
        for name in _robot_names(runs):
            rows.append(
                [str(label), _robot_label(name)]
                + [
                    fmt(cell_stat(runs, _get("localization", name, key)), 3)
                    for _, key in LOCALIZATION_COLUMNS
                ]
            )
        aligned = cell_stat(runs, _get("team_alignment", "aligned_rmse_m"))
        if aligned is not None:
            blanks = [""] * (len(LOCALIZATION_COLUMNS) - 3)
            rows.append([str(label), "team, aligned", "", "", fmt(aligned, 3), *blanks])
    return Table(
        title,
        ["run", "robot"] + [c for c, _ in LOCALIZATION_COLUMNS],
        rows,
        "team, aligned: the position RMSE of all robots after the one rigid motion that best "
        "lays the team's trajectories onto the truth (metrics.json's team_alignment); the "
        "robots' RMSE beyond it is the whole map turned or shifted against the start frame.",
    )


def coverage_table(experiment: int, teams: dict[int, list[RunOutcome]]) -> Table:
    """Thesis Table 5.3 layout: area and rate of every robot combination, beside the thesis's."""
    rows = []
    for robots, runs in teams.items():
        thesis = thesis_data.thesis_coverage(experiment, robots)
        names = [f"robot_{i}" for i in range(robots)]
        keys = [
            k for r in runs if r.metrics for k in r.metrics["coverage"] if "+" in k or k in names
        ]
        for key in dict.fromkeys(sorted(keys, key=lambda k: (k.count("+"), k))):
            area = cell_stat(runs, _get("coverage", key, "area_m2"))
            rate = cell_stat(runs, _get("coverage", key, "rate"))
            theirs = thesis.get(key)
            rows.append(
                [
                    f"{experiment}.{robots}",
                    ", ".join(_robot_label(n) for n in key.split("+")),
                    fmt(area, 2),
                    fmt(rate, 1, 100),
                    fmt_value(theirs[0] if theirs else None, 2),
                    fmt_value(100 * theirs[1] if theirs else None, 2),
                ]
            )
        explored = cell_stat(runs, _get("coverage", "explored_fraction_of_reachable"))
        rows.append(
            [
                f"{experiment}.{robots}",
                "explored / reachable area",
                "",
                fmt(explored, 1, 100),
                "",
                "",
            ]
        )
    return Table(
        f"Experiment {experiment}: exploration coverage per robot combination "
        f"(thesis {thesis_data.COVERAGE_SOURCE[experiment]})",
        ["run", "robots", "ours area [m²]", "ours rate [%]", "thesis area [m²]", "thesis rate [%]"],
        rows,
        "Rate: the combination's area over the whole team's (the team is 100 %).",
    )


MAPPING_ROWS = (
    ("Accuracy", "accuracy"),
    ("True Positive Rate (TPR)", "tpr"),
    ("True Negative Rate (TNR)", "tnr"),
    ("False Positive Rate (FPR)", "fpr"),
    ("False Negative Rate (FNR)", "fnr"),
)


def waste_table(title: str, teams: dict[object, list[RunOutcome]]) -> Table:
    """What exploring spent beyond the map: distance per robot and the overlap ratio."""
    rows = []
    for label, runs in teams.items():
        rows += [
            [str(label), _robot_label(name),
             fmt(cell_stat(runs, _get("waste", "travelled_m", name)), 1), ""]
            for name in _robot_names(runs)
        ]  # fmt: skip
        rows.append(
            [str(label), "team",
             fmt(cell_stat(runs, _get("waste", "travelled_total_m")), 1),
             fmt(cell_stat(runs, _get("waste", "overlap_ratio")), 1, 100)]
        )  # fmt: skip
    return Table(
        title,
        ["run", "robot", "distance travelled [m]", "overlap ratio [%]"],
        rows,
        "Overlap ratio: area mapped by more than one robot's own scans over the area mapped "
        "by any. Distances along the true paths. Every run, completed or not.",
    )


def mapping_table(title: str, teams: dict[object, list[RunOutcome]]) -> Table:
    """Thesis Table 5.4 layout: confusion rates of the final map, one column per run."""
    rows = [
        [label] + [fmt(cell_stat(runs, _get("mapping", key)), 1, 100) for runs in teams.values()]
        for label, key in MAPPING_ROWS
    ]
    return Table(title, ["metric [%]"] + [str(k) for k in teams], rows)


def _starts_text(starts: tuple[tuple[float, float, float], ...]) -> str:
    headings = {round(math.degrees(theta)) for _, _, theta in starts}
    poses = ", ".join(f"({x:.1f}, {y:.1f})" for x, y, _ in starts)
    facing = ", ".join(f"{h}°" for h in sorted(headings))
    return f"{poses}, facing {facing}"


def worlds_table(experiments: list[tuple[int, dict[int, list[RunOutcome]]]]) -> Table:
    """How our layouts differ from the thesis's labs: the text is all the thesis gives."""
    rows = []
    for experiment, teams in experiments:
        layout = thesis_layout(experiment)
        runs = [r for team in teams.values() for r in team]
        # The same world in every run: one value, not a spread.
        reachable = cell_stat(runs, _get("coverage", "reachable_area_m2"))
        rows.append(
            [
                f"exp{experiment}",
                layout.summary,
                fmt_value(reachable.mean if reachable else None, 1),
                str(len(layout.start_openings)),
                _starts_text(layout.starts),
                thesis_data.ENVIRONMENT[experiment],
                fmt_value(thesis_data.thesis_team_area_m2(experiment), 2),
            ]
        )
    return Table(
        "Our worlds and the thesis's labs (§5.2)",
        [
            "experiment",
            "ours: layout",
            "ours: reachable free area [m²]",
            "ours: openings of the start area",
            "ours: starts [x, y in m] (robot_0, robot_1, robot_2)",
            "thesis: environment",
            "thesis: area the team mapped [m²]",
        ],
        rows,
        "The thesis shows its labs only as photos, so our layouts keep what its text states: "
        "the initial frontiers and about the area the team mapped. Their distances, and so "
        f"the exploration times, are ours. Thesis starts: {thesis_data.STARTS} (§5.4).",
    )


def thesis_sections(cells: dict[Cell, list[RunOutcome]]) -> list[Section]:
    sections = []
    speedups = []
    for experiment in range(1, 6):
        teams = _thesis_cells(cells, experiment)
        if not teams:
            continue
        labelled = {f"{experiment}.{r}": runs for r, runs in teams.items()}
        first = 4 * experiment - 3
        sections.append(
            Section(
                f"Experiment {experiment} (thesis §5.5.{experiment})",
                f"thesis-exp{experiment}, planner {DEFAULT_PLANNER}, allocator "
                f"{DEFAULT_ALLOCATOR}; run {experiment}.N has N robots.",
                [
                    timing_table(experiment, teams),
                    localization_table(
                        f"Experiment {experiment}: position and orientation accuracy "
                        f"(thesis Table 5.{first + 1})"
                        if experiment < 5
                        else f"Experiment {experiment}: position and orientation accuracy "
                        "(not reported by the thesis)",
                        labelled,
                    ),
                    coverage_table(experiment, teams),
                    waste_table(
                        f"Experiment {experiment}: distance travelled and overlap "
                        "(not reported by the thesis)",
                        labelled,
                    ),
                    mapping_table(
                        f"Experiment {experiment}: mapping accuracy, confusion-based rates "
                        f"(thesis Table 5.{first + 3 if experiment < 5 else 18})",
                        labelled,
                    ),
                ],
            )
        )
        speedups.append((experiment, teams))
    if speedups:
        sections.insert(0, Section("Worlds", tables=[worlds_table(speedups)]))
        sections.append(Section("Speed-up over one robot", tables=[speedup_table(speedups)]))
    return sections


def speedup_table(experiments: list[tuple[int, dict[int, list[RunOutcome]]]]) -> Table:
    """Team exploration time per robot count and its speed-up over one robot, both sources."""
    rows = []
    for experiment, teams in experiments:
        totals = {r: cell_stat(runs, _get("timing", "total_s"), True) for r, runs in teams.items()}
        thesis = {
            r: (thesis_data.thesis_timing(experiment, r) or {}).get("total") for r in (1, 2, 3)
        }
        row = [f"exp{experiment}"]
        for robots in (1, 2, 3):
            row += [fmt(totals.get(robots)), fmt_value(thesis[robots], 1)]
        for robots in (2, 3):
            ours = _speedup(totals.get(1), totals.get(robots))
            theirs = f"{thesis[1] / thesis[robots]:.2f}x" if thesis[1] and thesis[robots] else "—"
            row += [ours, theirs]
        rows.append(row)
    header = ["experiment"]
    for robots in (1, 2, 3):
        header += [f"ours {robots}R [s]", f"thesis {robots}R [s]"]
    header += ["ours 2R/1R", "thesis 2R/1R", "ours 3R/1R", "thesis 3R/1R"]
    return Table(
        "Team exploration time and speed-up of 2 and 3 robots over 1 (Tables 5.1, 5.5, 5.9, 5.13)",
        header,
        rows,
        "Speed-up: mean time of one robot over mean time of the team; completed runs only.",
    )


COMPARISON_COLUMNS = [
    "scenario",
    "robots",
    "planner",
    "allocator",
    "completed",
    "exploration time [s]",
    "explored [%]",
    "overlap ratio [%]",
    "team distance [m]",
    "stuck events",
    "min separation [m]",
    "wall collisions",
    "robot collisions",
]


def _comparison_row(cell: Cell, runs: list[RunOutcome]) -> list[str]:
    scenario, robots, planner, allocator = cell
    return [
        scenario,
        str(robots),
        planner,
        allocator,
        completion(runs),
        fmt(cell_stat(runs, _get("timing", "total_s"), True)),
        fmt(cell_stat(runs, _get("coverage", "explored_fraction_of_reachable")), 1, 100),
        fmt(cell_stat(runs, _get("waste", "overlap_ratio")), 1, 100),
        fmt(cell_stat(runs, _get("waste", "travelled_total_m")), 1),
        fmt(cell_stat(runs, _get("safety", "stuck_events"))),
        fmt(cell_stat(runs, _get("safety", "min_robot_distance_m")), 2),
        fmt(cell_stat(runs, _get("safety", "obstacle_collisions"))),
        fmt(cell_stat(runs, _get("safety", "robot_collisions"))),
    ]


def comparison_sections(cells: dict[Cell, list[RunOutcome]]) -> list[Section]:
    """Cells that differ only in the allocator (or only in the planner), side by side."""
    tables = []
    for varied, index in (("allocator", 3), ("planner", 2)):
        groups: dict[tuple, list[Cell]] = defaultdict(list)
        for cell in sorted(cells):
            groups[tuple(v for i, v in enumerate(cell) if i != index)].append(cell)
        rows = [
            _comparison_row(cell, cells[cell])
            for members in groups.values()
            if len(members) > 1
            for cell in members
        ]
        if rows:
            tables.append(
                Table(
                    f"{varied.capitalize()} comparison",
                    COMPARISON_COLUMNS,
                    rows,
                    "Exploration time: completed runs only; the rest: every run. Min "
                    "separation: closest approach of two robot centres (ground truth).",
                )
            )
    if not tables:
        return []
    return [Section("Algorithm comparisons", tables=tables)]


def scaling_sections(cells: dict[Cell, list[RunOutcome]]) -> list[Section]:
    """Scenarios other than the thesis's: time, server cycle and real-time factor per team."""
    chosen = {c: runs for c, runs in sorted(cells.items()) if not _THESIS_SCENARIO.match(c[0])}
    if not chosen:
        return []
    smallest: dict[str, Stat | None] = {}
    rows, module_rows = [], []
    modules = sorted(
        {
            k
            for runs in chosen.values()
            for r in runs
            if r.metrics
            for k, v in r.metrics["server_cycle_ms"].items()
            if isinstance(v, dict)
        }
    )
    for cell, runs in chosen.items():
        scenario, robots, planner, allocator = cell
        label = scenario
        if (planner, allocator) != (DEFAULT_PLANNER, DEFAULT_ALLOCATOR):
            label += f" ({planner}, {allocator})"
        total = cell_stat(runs, _get("timing", "total_s"), True)
        base = smallest.setdefault(label, total)
        rows.append(
            [
                label,
                str(robots),
                completion(runs),
                fmt(total),
                _speedup(base, total),
                fmt(cell_stat(runs, _get("coverage", "explored_fraction_of_reachable")), 1, 100),
                fmt(cell_stat(runs, _get("waste", "overlap_ratio")), 1, 100),
                fmt(cell_stat(runs, _get("waste", "travelled_total_m")), 1),
                fmt(cell_stat(runs, _get("server_cycle_ms", "mean")), 1),
                fmt(cell_stat(runs, _get("server_cycle_ms", "p95")), 1),
                fmt(cell_stat(runs, _get("real_time_factor")), 2),
            ]
        )
        module_rows.append(
            [label, str(robots)]
            + [
                f"{fmt(cell_stat(runs, _get('server_cycle_ms', m, 'mean')), 1)} / "
                f"{fmt(cell_stat(runs, _get('server_cycle_ms', m, 'p95')), 1)}"
                for m in modules
            ]
        )
    return [
        Section(
            "Team scaling",
            "Scenarios other than the thesis experiments, per team size. Server cycle: wall "
            "time of one server step (control period 100 ms); real-time factor: simulated "
            "over wall seconds of the whole run (simulator and server in one process).",
            [
                Table(
                    "Exploration time, server cycle and real-time factor",
                    [
                        "scenario",
                        "robots",
                        "completed",
                        "exploration time [s]",
                        "speed-up over smallest team",
                        "explored [%]",
                        "overlap ratio [%]",
                        "team distance [m]",
                        "cycle mean [ms]",
                        "cycle p95 [ms]",
                        "real-time factor",
                    ],
                    rows,
                ),
                Table(
                    "Server cycle per module, mean / p95 [ms]",
                    ["scenario", "robots", *modules],
                    module_rows,
                ),
            ],
        )
    ]


def runs_section(runs: list[RunOutcome]) -> Section:
    rows = [
        [
            r.run_id,
            r.status,
            r.reason,
            fmt_value(r.metrics["sim_time_s"] if r.metrics else None),
            fmt_value(r.metrics["wall_time_s"] if r.metrics else None),
        ]
        for r in runs
    ]
    return Section(
        "Every run",
        "",
        [Table("Runs", ["run", "status", "reason", "sim time [s]", "wall time [s]"], rows)],
    )


def build_sections(runs: list[RunOutcome]) -> list[Section]:
    cells = by_cell(runs)
    return [
        *thesis_sections(cells),
        *comparison_sections(cells),
        *scaling_sections(cells),
        runs_section(runs),
    ]


# --------------------------------------------------------------------------- rendering


def _overview(runs: list[RunOutcome]) -> str:
    counts: dict[str, int] = defaultdict(int)
    for r in runs:
        counts[r.status] += 1
    seeds = sorted({r.spec["seed"] for r in runs})
    return (
        f"{plural(len(runs), 'run')} ({', '.join(f'{n} {s}' for s, n in counts.items())}); seeds "
        f"{', '.join(map(str, seeds))}. Cells: mean ± sample std over seeds (one value: no std). "
        "Exploration times and speed-ups: completed runs only; other figures: every run "
        "that wrote metrics. Thesis figures: real TurtleBot3 runs, one trial each (§5.5)."
    )


def to_markdown(title: str, runs: list[RunOutcome], sections: list[Section]) -> str:
    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    lines = [f"# {title}", "", _overview(runs), ""]
    for section in sections:
        lines += [f"## {section.title}", ""]
        if section.intro:
            lines += [section.intro, ""]
        for table in section.tables:
            lines += [f"### {table.title}", ""]
            lines.append("| " + " | ".join(cell(h) for h in table.header) + " |")
            lines.append("|" + "---|" * len(table.header))
            lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in table.rows]
            lines.append("")
            if table.note:
                lines += [table.note, ""]
    return "\n".join(lines)


STYLE = """
body { font-family: sans-serif; margin: 2em; max-width: 1400px; }
table { border-collapse: collapse; margin-bottom: 0.5em; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: right; }
th { background: #eee; }
td:first-child { text-align: left; }
tr.fail td { background: #fde2e2; }
p.note { color: #555; font-size: 90%; margin-top: 0; }
"""


def to_html(title: str, runs: list[RunOutcome], sections: list[Section]) -> str:
    """One self-contained page; rows of runs that did not complete are tinted."""
    parts = [f"<h1>{html.escape(title)}</h1><p>{html.escape(_overview(runs))}</p>"]
    for section in sections:
        parts.append(f"<h2>{html.escape(section.title)}</h2>")
        if section.intro:
            parts.append(f"<p>{html.escape(section.intro)}</p>")
        for table in section.tables:
            head = "".join(f"<th>{html.escape(h)}</th>" for h in table.header)
            body = "".join(
                ("<tr class='fail'>" if _is_failure(row) else "<tr>")
                + "".join(f"<td>{html.escape(c)}</td>" for c in row)
                + "</tr>"
                for row in table.rows
            )
            parts.append(
                f"<h3>{html.escape(table.title)}</h3>"
                f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
            )
            if table.note:
                parts.append(f"<p class='note'>{html.escape(table.note)}</p>")
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
        + "\n".join(parts)
        + "</body></html>\n"
    )


def _is_failure(row: list[str]) -> bool:
    return any(
        c in ("failed", "not completed", "not run yet") or re.match(r"^\d+/\d+ \(", c) for c in row
    )


def write_summary(out_dir: Path, title: str = "acslam experiments") -> tuple[Path, Path]:
    """Write ``summary.md`` and ``summary.html`` of the sweep in ``out_dir``."""
    out_dir = Path(out_dir)
    runs = load_runs(out_dir)
    sections = build_sections(runs)
    markdown = out_dir / "summary.md"
    page = out_dir / "summary.html"
    write_text(markdown, to_markdown(title, runs, sections))
    write_text(page, to_html(title, runs, sections))
    return markdown, page
