"""Run reports: the figures of thesis chapter 5 and a self-contained report.html.

A run saves a :class:`RunRecord` (``run.npz``) beside ``metrics.json``; figures and the
report are made from those two files only, so ``acslam report DIR`` can rebuild them
without running anything again.
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path

import numpy as np

from acslam.errors import DataError
from acslam.eval.figures import robot_colour
from acslam.eval.plotting import plt
from acslam.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from acslam.text import plural

# Thesis Fig. 5.12: green TP, white TN, blue FP, red FN (grey: not mapped).
CONFUSION_COLOURS = {
    "tp": (0.13, 0.62, 0.23),
    "tn": (1.0, 1.0, 1.0),
    "fp": (0.15, 0.35, 0.9),
    "fn": (0.85, 0.1, 0.1),
    "unknown": (0.6, 0.6, 0.6),
}


@dataclass
class RunRecord:
    """Everything the figures need: maps, masks, trajectories ``[t, x, y, theta]``, and
    each server stage's wall time ``[simulated time s, wall s]`` each time it ran
    (``stage_timings[k]`` for ``stage_names[k]``; empty in records written before)."""

    spec: GridSpec
    true_occupied: np.ndarray
    reachable: np.ndarray
    estimated_values: np.ndarray
    robot_known: np.ndarray
    estimated_trajectories: list[np.ndarray]
    true_trajectories: list[np.ndarray]
    explored_history: np.ndarray
    landmarks_true: np.ndarray
    landmarks_estimated: np.ndarray
    stage_names: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=str))
    stage_timings: list[np.ndarray] = field(default_factory=list)
    control_period_s: float = 0.1

    def save(self, path: Path) -> None:
        arrays: dict[str, np.ndarray] = {
            "spec": np.array(
                [
                    self.spec.origin_x_m,
                    self.spec.origin_y_m,
                    self.spec.resolution_m,
                    self.spec.rows,
                    self.spec.cols,
                ]
            ),
        }
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "spec":
                continue
            if isinstance(value, list):
                for i, item in enumerate(value):
                    arrays[f"{f.name}.{i}"] = item
            else:
                arrays[f.name] = value
        np.savez_compressed(path, **arrays)

    @classmethod
    def load(cls, path: Path) -> RunRecord:
        try:
            data = np.load(path)
            x0, y0, res, rows, cols = data["spec"]
            values = {"spec": GridSpec(float(x0), float(y0), float(res), int(rows), int(cols))}
            for f in fields(cls):
                if f.name == "spec":
                    continue
                items = sorted(
                    (k for k in data if k.startswith(f.name + ".")),
                    key=lambda k: int(k.rsplit(".", 1)[1]),
                )
                if f.name in data:
                    values[f.name] = data[f.name]
                elif items or (f.default is MISSING and f.default_factory is MISSING):
                    values[f.name] = [data[k] for k in items]
                # else: written before the field existed, so it keeps its default
            return cls(**values)
        except (OSError, KeyError, ValueError) as exc:
            raise DataError(path, f"not a run record ({exc})") from None


# --------------------------------------------------------------------------- figures


def _zoom(ax: plt.Axes, record: RunRecord, margin_m: float = 1.0) -> None:
    """Frame the reachable area (the 40 m grids are mostly wall)."""
    rows, cols = np.nonzero(record.reachable | (record.estimated_values != UNKNOWN))
    if len(rows) == 0:
        return
    spec = record.spec
    ax.set_xlim(
        spec.origin_x_m + cols.min() * spec.resolution_m - margin_m,
        spec.origin_x_m + (cols.max() + 1) * spec.resolution_m + margin_m,
    )
    ax.set_ylim(
        spec.origin_y_m + rows.min() * spec.resolution_m - margin_m,
        spec.origin_y_m + (rows.max() + 1) * spec.resolution_m + margin_m,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _map_image(values: np.ndarray) -> np.ndarray:
    """OccupancyGrid values as grey levels: white free, black occupied, grey unknown."""
    image = np.full(values.shape, 0.6)
    image[values == FREE] = 1.0
    image[values == OCCUPIED] = 0.0
    return image


def _save(fig: plt.Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _show_grey(ax: plt.Axes, image: np.ndarray, record: RunRecord, alpha: float = 1.0) -> None:
    """A [0, 1] grey image of the run's grid, in metres, row 0 at the bottom."""
    ax.imshow(
        image,
        cmap="gray",
        origin="lower",
        extent=record.spec.extent_m,
        vmin=0,
        vmax=1,
        interpolation="nearest",
        alpha=alpha,
    )


def figure_trajectories(record: RunRecord, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    _show_grey(ax, ~record.true_occupied, record, alpha=0.5)
    for i, (est, true) in enumerate(
        zip(record.estimated_trajectories, record.true_trajectories, strict=True)
    ):
        ax.plot(
            true[:, 1],
            true[:, 2],
            color="k",
            lw=0.8,
            ls="--",
            label="ground truth" if i == 0 else None,
        )
        ax.plot(est[:, 1], est[:, 2], color=robot_colour(i), lw=1.5, label=f"robot_{i} estimated")
    if len(record.landmarks_estimated):
        ax.scatter(
            *record.landmarks_estimated[:, :2].T,
            s=8,
            c="tab:blue",
            marker="x",
            label="landmarks (estimated)",
        )
    _zoom(ax, record)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("Estimated vs ground-truth trajectories")
    _save(fig, path)


def figure_map(values: np.ndarray, record: RunRecord, path: Path, title: str) -> None:
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    _show_grey(ax, _map_image(values), record)
    _zoom(ax, record)
    ax.set_title(title)
    _save(fig, path)


def confusion_image(true_occupied: np.ndarray, values: np.ndarray) -> np.ndarray:
    """RGB image of the confusion classes in the thesis's colours."""
    image = np.empty((*values.shape, 3))
    image[:] = CONFUSION_COLOURS["unknown"]
    predicted = values == OCCUPIED
    known = values != UNKNOWN
    image[known & predicted & true_occupied] = CONFUSION_COLOURS["tp"]
    image[known & ~predicted & ~true_occupied] = CONFUSION_COLOURS["tn"]
    image[known & predicted & ~true_occupied] = CONFUSION_COLOURS["fp"]
    image[known & ~predicted & true_occupied] = CONFUSION_COLOURS["fn"]
    return image


def figure_confusion(record: RunRecord, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    ax.imshow(
        confusion_image(record.true_occupied, record.estimated_values),
        origin="lower",
        extent=record.spec.extent_m,
        interpolation="nearest",
    )
    _zoom(ax, record)
    ax.set_title("Confusion map: green TP, white TN, blue FP, red FN")
    _save(fig, path)


def figure_explored(record: RunRecord, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 3.5), dpi=110)
    history = record.explored_history
    if len(history):
        ax.plot(history[:, 0], history[:, 1], color="tab:green")
    reachable_m2 = record.reachable.sum() * record.spec.resolution_m**2
    ax.axhline(reachable_m2, color="k", ls=":", label=f"reachable free area {reachable_m2:.1f} m²")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mapped area [m²]")
    ax.legend(fontsize=8)
    ax.set_title("Explored area over time")
    _save(fig, path)


TIMING_WINDOW_S = 10.0
"""Simulated seconds per point of the cycle-time figure (its p95 over the window)."""


def figure_cycle_time(record: RunRecord, path: Path) -> None:
    """p95 of the whole cycle and of each stage per 10 s of simulated time, against the
    control period: whether the cost of a cycle grows as the run goes on."""
    fig, ax = plt.subplots(figsize=(7, 3.5), dpi=110)
    for name, samples in zip(record.stage_names, record.stage_timings, strict=True):
        if len(samples) == 0:
            continue
        windows = np.floor(samples[:, 0] / TIMING_WINDOW_S).astype(int)
        starts = np.unique(windows)
        p95_ms = [1000 * np.percentile(samples[windows == w, 1], 95) for w in starts]
        style = {"color": "k", "lw": 2} if name == "cycle" else {"lw": 1}
        ax.plot((starts + 0.5) * TIMING_WINDOW_S, p95_ms, label=str(name), **style)
    period_ms = 1000 * float(record.control_period_s)
    ax.axhline(period_ms, color="tab:red", ls=":", label=f"control period {period_ms:.0f} ms")
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel(f"p95 per {TIMING_WINDOW_S:.0f} s [ms]")
    ax.set_yscale("log")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Server cycle and stages over the run")
    _save(fig, path)


def write_figures(out_dir: Path, record: RunRecord) -> list[Path]:
    folder = Path(out_dir) / "figures"
    folder.mkdir(parents=True, exist_ok=True)
    paths = [
        folder / "trajectories.png",
        folder / "map.png",
        folder / "confusion.png",
        folder / "explored_area.png",
    ]
    figure_trajectories(record, paths[0])
    figure_map(record.estimated_values, record, paths[1], "Final map (all robots)")
    figure_confusion(record, paths[2])
    figure_explored(record, paths[3])
    if record.stage_timings:
        paths.append(folder / "cycle_time.png")
        figure_cycle_time(record, paths[-1])
    for i, known in enumerate(record.robot_known):
        values = np.where(known, record.estimated_values, -1)
        path = folder / f"exploration_robot_{i}.png"
        figure_map(values, record, path, f"Area mapped by robot_{i}")
        paths.append(path)
    return paths


# --------------------------------------------------------------------------- html


def _number(value: object, digits: int = 3) -> str:
    if value is None:  # no number: e.g. the exploration time of a robot still exploring
        return "—"
    if isinstance(value, float):
        return "—" if math.isnan(value) else f"{value:.{digits}f}"
    return html.escape(str(value))


def _table(header: list[str], rows: list[list[object]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{_number(c)}</td>" for c in row) + "</tr>" for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _cycle_table(cycle_ms: dict) -> str:
    """Whole cycle and stages: mean, p95, p99, max, and p95 as a share of the control
    period (runs written before p99 and max were recorded show a dash there)."""
    period_ms = cycle_ms.get("control_period_ms", math.nan)
    rows = [("whole cycle", cycle_ms)] + [
        (k, v) for k, v in cycle_ms.items() if isinstance(v, dict)
    ]
    return _table(
        ["stage", "mean", "p95", "p99", "max", "p95 / control period"],
        [
            [name, *(float(v.get(k, math.nan)) for k in ("mean", "p95", "p99", "max")),
             float(v["p95"]) / period_ms]
            for name, v in rows
        ],
    )  # fmt: skip


def report_tables(metrics: dict) -> dict[str, str]:
    """The run's tables in the layout of thesis Tables 5.1-5.4, as HTML."""
    timing = metrics["timing"]
    tables = {
        "Timing (Table 5.1)": _table(
            ["robot", "exploration time [s]"],
            [[name, t] for name, t in timing["per_robot_s"].items()]
            + [["total", timing["total_s"]], ["gap", timing["gap_s"]]],
        ),
        "Localization (Table 5.2)": _table(
            [
                "robot",
                "final dist. [m]",
                "MAE [m]",
                "RMSE [m]",
                "STD [m]",
                "final yaw [rad]",
                "MAE [rad]",
                "RMSE [rad]",
                "STD [rad]",
            ],
            [
                [
                    name,
                    m["final_dist_m"],
                    m["mae_m"],
                    m["rmse_m"],
                    m["std_m"],
                    m["final_yaw_rad"],
                    m["mae_yaw_rad"],
                    m["rmse_yaw_rad"],
                    m["std_yaw_rad"],
                ]
                for name, m in metrics["localization"].items()
            ],
        ),
        "Coverage per robot combination (Table 5.3)": _table(
            ["robots", "area [m²]", "rate [%]"],
            [
                [name.replace("+", ", "), c["area_m2"], 100 * c["rate"]]
                for name, c in metrics["coverage"].items()
                if isinstance(c, dict)
            ]
            + [
                [
                    "explored fraction of the reachable free area [%]",
                    "",
                    100 * metrics["coverage"]["explored_fraction_of_reachable"],
                ]
            ],
        ),
        "Mapping accuracy (Table 5.4)": _table(
            ["metric", "value [%]"],
            [
                [k.upper(), 100 * metrics["mapping"][k]]
                for k in ("accuracy", "tpr", "tnr", "fpr", "fnr")
            ],
        ),
        "Safety": _table(["metric", "value"], [[k, v] for k, v in metrics["safety"].items()]),
        "Server cycle [ms]": _cycle_table(metrics["server_cycle_ms"]),
    }
    return tables


def write_report(out_dir: Path, record: RunRecord, metrics: dict) -> Path:
    """Write figures/ and report.html (figures embedded, so the file stands alone)."""
    out_dir = Path(out_dir)
    figures = write_figures(out_dir, record)
    status = "completed" if metrics["completed"] else f"not completed ({metrics['reason']})"
    summary = (
        f"{metrics['scenario']}: {plural(metrics['robots'], 'robot')}, "
        f"planner {metrics['planner']}, allocator {metrics['allocator']}, "
        f"seed {metrics['seed']}: {status} after "
        f"{metrics['sim_time_s']:.1f} s simulated in {metrics['wall_time_s']:.1f} s wall time "
        f"({metrics['real_time_factor']:.1f}x real time)."
    )
    sections = "".join(
        f"<h2>{html.escape(title)}</h2>{table}" for title, table in report_tables(metrics).items()
    )
    images = "".join(
        f'<figure><img alt="{p.stem}" src="data:image/png;base64,'
        f'{base64.b64encode(p.read_bytes()).decode()}"><figcaption>{p.stem}</figcaption></figure>'
        for p in figures
    )
    title = html.escape(f"acslam run: {metrics['scenario']}")
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1100px; }}
table {{ border-collapse: collapse; margin-bottom: 1em; }}
td, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: right; }}
th {{ background: #eee; }}
figure {{ display: inline-block; margin: 0.5em; }}
img {{ max-width: 520px; }}
</style></head><body>
<h1>acslam run report</h1><p>{html.escape(summary)}</p>
{sections}<h2>Figures</h2>{images}
</body></html>
"""
    path = out_dir / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def rebuild_report(out_dir: Path) -> Path:
    """Re-make figures and report.html of a finished run from its saved files."""
    out_dir = Path(out_dir)
    metrics_path = out_dir / "metrics.json"
    try:
        metrics = json.loads(metrics_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(metrics_path, "not found: is this a run folder?") from None
    except json.JSONDecodeError as exc:
        raise DataError(metrics_path, f"not valid JSON ({exc.msg})", exc.lineno) from None
    return write_report(out_dir, RunRecord.load(out_dir / "run.npz"), metrics)
