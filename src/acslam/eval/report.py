"""Run reports: the figures of thesis chapter 5 and a self-contained report.html.

A run saves a :class:`RunRecord` (``run.npz``) beside ``metrics.json``; figures and the
report are made from those two files only, so ``acslam report DIR`` can rebuild them
without running anything again. It reads and checks both (:class:`ReportedMetrics`)
before it writes anything.
"""

from __future__ import annotations

import base64
import html
import math
import zipfile
import zlib
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from acslam.config import validated
from acslam.errors import DataError
from acslam.eval.figures import robot_colour
from acslam.eval.metrics import explored_areas, waste
from acslam.eval.plotting import plt, save_figure
from acslam.files import atomic_path, read_json, write_text
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
    (``stage_timings[k]`` for ``stage_names[k]``; empty in records written before).

    ``estimated_trajectories`` are the keyframes as the final estimate places them;
    ``online_trajectories`` each robot's pose as the server used it at every step, before
    any later correction (what it drove and mapped by; empty in records written before).
    """

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
    online_trajectories: list[np.ndarray] = field(default_factory=list)

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
        with atomic_path(path) as temporary:
            np.savez_compressed(temporary, **arrays)

    @classmethod
    def load(cls, path: Path) -> RunRecord:
        """The record saved at ``path``, every array read and the grids' shapes checked,
        or a DataError."""
        try:
            with np.load(path) as data:
                x0, y0, res, rows, cols = data["spec"]
                spec = GridSpec(float(x0), float(y0), float(res), int(rows), int(cols))
                values: dict[str, object] = {"spec": spec}
                for f in fields(cls):
                    if f.name == "spec":
                        continue
                    required = f.default is MISSING and f.default_factory is MISSING
                    items = sorted(
                        (k for k in data if k.startswith(f.name + ".")),
                        key=lambda k: int(k.rsplit(".", 1)[1]),
                    )
                    if f.name in data:
                        values[f.name] = data[f.name]
                    elif str(f.type).startswith("list[") and (items or required):
                        values[f.name] = [data[k] for k in items]
                    elif required:
                        raise KeyError(f"no array {f.name!r}")
                    # else: written before the field existed, so it keeps its default
            record = cls(**values)
            for name in ("true_occupied", "reachable", "estimated_values"):
                if getattr(record, name).shape != spec.shape:
                    raise ValueError(f"{name} is not of the grid's shape {spec.shape}")
            return record
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise DataError(path, f"not a run record ({exc})") from None

    def waste(self, names: list[str]) -> dict[str, object]:
        """Overlap and distance travelled (:func:`acslam.eval.metrics.waste`) of the robots
        ``names`` (in robot order): along the true paths, or the estimated ones where a
        real team has no truth."""
        has_truth = all(len(true) for true in self.true_trajectories)
        driven = self.true_trajectories if has_truth else self.estimated_trajectories
        return waste(
            dict(zip(names, self.robot_known, strict=True)),
            {name: path[:, 1:3] for name, path in zip(names, driven, strict=True)},
            self.spec.resolution_m**2,
            "ground truth" if has_truth else "estimate",
        )


# --------------------------------------------------------------------------- figures

FIGURE_DPI = 100
MAP_WIDTH_IN = 7.0
"""Width of the axes of a full-size map; its height follows the mapped region."""
ROBOT_MAP_WIDTH_IN = 4.2
"""Width of the axes of one robot's map, two of which sit side by side in the report."""
MAX_MAP_HEIGHT_IN = 7.0
MAP_GREYS = {"free": 1.0, "occupied": 0.0, "unknown": 0.6}


@dataclass(frozen=True)
class ReportFigure:
    """A figure file and the caption the report prints under it."""

    path: Path
    caption: str
    wide: bool = True
    """Shown across the page (False: half its width, beside the next one)."""


def _map_region(record: RunRecord, margin_m: float = 1.0) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) framing the reachable and mapped area (the 40 m grids are mostly
    wall), with a margin that stays on the grid."""
    rows, cols = np.nonzero(record.reachable | (record.estimated_values != UNKNOWN))
    spec = record.spec
    left, right, bottom, top = spec.extent_m
    if len(rows) == 0:
        return left, right, bottom, top
    return (
        max(left, spec.origin_x_m + cols.min() * spec.resolution_m - margin_m),
        min(right, spec.origin_x_m + (cols.max() + 1) * spec.resolution_m + margin_m),
        max(bottom, spec.origin_y_m + rows.min() * spec.resolution_m - margin_m),
        min(top, spec.origin_y_m + (rows.max() + 1) * spec.resolution_m + margin_m),
    )


def _map_axes(record: RunRecord, width_in: float = MAP_WIDTH_IN) -> tuple[plt.Figure, plt.Axes]:
    """A figure whose axes frame the run's region in metres at equal scale, sized to it."""
    x0, x1, y0, y1 = _map_region(record)
    height_in = width_in * (y1 - y0) / (x1 - x0)
    if height_in > MAX_MAP_HEIGHT_IN:
        width_in, height_in = width_in * MAX_MAP_HEIGHT_IN / height_in, MAX_MAP_HEIGHT_IN
    fig, ax = plt.subplots(figsize=(width_in + 1.0, height_in + 0.8), dpi=FIGURE_DPI)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return fig, ax


def _key_beside(ax: plt.Axes, handles: list, **legend: object) -> None:
    """The colour key right of the axes (cropping takes it in), never over the map."""
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.02, 1.0),
        borderaxespad=0.0,
        fontsize=8,
        frameon=False,
        **legend,
    )


def _key_below(ax: plt.Axes, handles: list) -> None:
    """The colour key in one row under the axes (for maps shown half a page wide)."""
    ax.legend(
        handles=handles,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.2),
        ncol=len(handles),
        fontsize=8,
        frameon=False,
        handlelength=1.2,
        columnspacing=1.0,
    )


def _swatch(colour: object, label: str) -> plt.Rectangle:
    """A legend entry for cells of one colour (edged, so white shows on white)."""
    return plt.Rectangle((0, 0), 1, 1, facecolor=colour, edgecolor="0.3", lw=0.5, label=label)


def _map_key(not_mapped: str) -> list:
    return [
        _swatch(str(MAP_GREYS["free"]), "free"),
        _swatch(str(MAP_GREYS["occupied"]), "occupied"),
        _swatch(str(MAP_GREYS["unknown"]), not_mapped),
    ]


def _map_image(values: np.ndarray) -> np.ndarray:
    """OccupancyGrid values as grey levels: white free, black occupied, grey unknown."""
    image = np.full(values.shape, MAP_GREYS["unknown"])
    image[values == FREE] = MAP_GREYS["free"]
    image[values == OCCUPIED] = MAP_GREYS["occupied"]
    return image


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
    """Each robot's estimate in its colour with its ground truth dashed on top (where the
    two agree the dashes still show), start and end marked."""
    fig, ax = _map_axes(record)
    _show_grey(ax, ~record.true_occupied, record, alpha=0.5)
    for i, (est, true) in enumerate(
        zip(record.estimated_trajectories, record.true_trajectories, strict=True)
    ):
        colour = robot_colour(i)
        ax.plot(est[:, 1], est[:, 2], color=colour, lw=2.0, zorder=2)
        if len(true):
            ax.plot(true[:, 1], true[:, 2], color="k", lw=0.8, ls=(0, (3, 2)), zorder=3)
        if len(est):
            ax.plot(*est[0, 1:3], "o", ms=8, color=colour, mec="k", zorder=4)
            ax.plot(*est[-1, 1:3], "s", ms=7, color=colour, mec="k", zorder=4)
    if len(record.landmarks_estimated):
        ax.scatter(*record.landmarks_estimated[:, :2].T, s=14, c="tab:blue", marker="x", zorder=5)
    handles = [
        plt.Line2D([], [], color=robot_colour(i), lw=2.0, label=f"robot_{i} estimated")
        for i in range(len(record.estimated_trajectories))
    ]
    handles += [
        plt.Line2D([], [], color="k", lw=0.8, ls=(0, (3, 2)), label="ground truth"),
        plt.Line2D([], [], ls="", marker="o", ms=8, color="w", mec="k", label="start"),
        plt.Line2D([], [], ls="", marker="s", ms=7, color="w", mec="k", label="end"),
    ]
    if len(record.landmarks_estimated):
        handles.append(
            plt.Line2D([], [], ls="", marker="x", color="tab:blue", label="landmark (estimated)")
        )
    handles.append(_swatch((0.5, 0.5, 0.5), "obstacle (true map)"))
    _key_beside(ax, handles)
    ax.set_title("Estimated and ground-truth trajectories")
    save_figure(fig, path)


def figure_map(values: np.ndarray, record: RunRecord, path: Path, title: str) -> None:
    fig, ax = _map_axes(record)
    _show_grey(ax, _map_image(values), record)
    _key_beside(ax, _map_key("not mapped"))
    ax.set_title(title)
    save_figure(fig, path)


def figure_robot_map(values: np.ndarray, record: RunRecord, path: Path, name: str) -> None:
    """One robot's own map, half a page wide, its key underneath."""
    fig, ax = _map_axes(record, ROBOT_MAP_WIDTH_IN)
    _show_grey(ax, _map_image(values), record)
    _key_below(ax, _map_key(f"not mapped by {name}"))
    ax.set_title(f"Area mapped by {name}")
    save_figure(fig, path)


CONFUSION_LABELS = {
    "tp": "true positive: occupied, mapped occupied",
    "tn": "true negative: free, mapped free",
    "fp": "false positive: free, mapped occupied",
    "fn": "false negative: occupied, mapped free",
    "unknown": "not mapped (not scored)",
}


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
    fig, ax = _map_axes(record)
    ax.imshow(
        confusion_image(record.true_occupied, record.estimated_values),
        origin="lower",
        extent=record.spec.extent_m,
        interpolation="nearest",
    )
    _key_beside(ax, [_swatch(CONFUSION_COLOURS[k], v) for k, v in CONFUSION_LABELS.items()])
    ax.set_title("Confusion map (positive: occupied)")
    save_figure(fig, path)


def figure_explored(record: RunRecord, path: Path) -> None:
    """The team map's mapped area over the run against the reachable free area."""
    fig, ax = plt.subplots(figsize=(9.0, 3.6), dpi=FIGURE_DPI)
    history = record.explored_history
    if len(history):
        ax.plot(
            history[:, 0], history[:, 1], color="tab:green", lw=1.8,
            label="mapped area of the team map (free or occupied cells)",
        )  # fmt: skip
    reachable_m2 = explored_areas(
        record.estimated_values != UNKNOWN, record.reachable, record.spec.resolution_m**2
    )["reachable_area_m2"]
    ax.axhline(
        reachable_m2,
        color="k",
        ls=":",
        label=f"reachable free area (true map), {reachable_m2:.1f} m²",
    )
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("area [m²]")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title("Mapped area over time")
    save_figure(fig, path)


TIMING_WINDOW_S = 10.0
"""Simulated seconds per point of the cycle-time figure (its p95 over the window)."""


def stage_label(name: str) -> str:
    """A stage's name as people write it ("local planning", "whole cycle")."""
    return "whole cycle" if name == "cycle" else name.replace("_", " ")


def window_p95_ms(samples: np.ndarray) -> tuple[list[float], list[float]]:
    """Of a stage's ``[simulated time s, wall s]`` samples: the centre of each
    ``TIMING_WINDOW_S`` window of simulated time that holds some, and their p95 in ms."""
    windows = np.floor(samples[:, 0] / TIMING_WINDOW_S).astype(int)
    starts = np.unique(windows)
    p95_ms = [float(1000 * np.percentile(samples[windows == w, 1], 95)) for w in starts]
    return ((starts + 0.5) * TIMING_WINDOW_S).tolist(), p95_ms


def figure_cycle_time(record: RunRecord, path: Path) -> None:
    """p95 of the whole cycle and of each stage per 10 s of simulated time, against the
    control period: whether the cost of a cycle grows as the run goes on."""
    fig, ax = plt.subplots(figsize=(9.0, 3.6), dpi=FIGURE_DPI)
    for name, samples in zip(record.stage_names, record.stage_timings, strict=True):
        if len(samples) == 0:
            continue
        style = {"color": "k", "lw": 2} if name == "cycle" else {"lw": 1}
        ax.plot(*window_p95_ms(samples), label=stage_label(str(name)), **style)
    period_ms = 1000 * float(record.control_period_s)
    ax.axhline(period_ms, color="tab:red", ls=":", label=f"control period {period_ms:.0f} ms")
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel(f"p95 per {TIMING_WINDOW_S:.0f} s [ms]")
    ax.set_yscale("log")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax.set_title("Server cycle and stages over the run")
    save_figure(fig, path)


def write_figures(out_dir: Path, record: RunRecord) -> list[ReportFigure]:
    """Every figure of the run under ``out_dir/figures``, with its caption."""
    folder = Path(out_dir) / "figures"
    count = len(record.estimated_trajectories)
    figures = [
        ReportFigure(
            folder / "trajectories.png",
            (
                "The robot's estimated trajectory (solid) and its ground truth"
                if count == 1
                else f"Estimated trajectories of the {count} robots (solid, one colour each) "
                "and their ground truth"
            )
            + " (black, dashed, drawn on top), from start (circle) to end (square), over the "
            "true map; crosses are the estimated landmarks.",
        ),
        ReportFigure(
            folder / "map.png",
            "The team's final occupancy map, made from every robot's scans.",
        ),
        ReportFigure(
            folder / "confusion.png",
            "The final map scored cell by cell against the true map, occupied being positive, "
            "in the colours of thesis Fig. 5.12: green and white cells are right, blue and "
            "red wrong; grey cells were not mapped and are left out of the mapping accuracy.",
        ),
        ReportFigure(
            folder / "explored_area.png",
            "Area the team map knows (free or occupied) each simulated second, against the "
            "free area a robot can reach. Walls and cells seen beyond reach count as mapped, "
            "so the curve can end above the line: see the explored-area table.",
        ),
    ]
    figure_trajectories(record, figures[0].path)
    figure_map(record.estimated_values, record, figures[1].path, "Final map")
    figure_confusion(record, figures[2].path)
    figure_explored(record, figures[3].path)
    if record.stage_timings:
        figures.append(
            ReportFigure(
                folder / "cycle_time.png",
                f"95th percentile of the server's cycle time and of each stage per "
                f"{TIMING_WINDOW_S:.0f} s of simulated time (log scale), against the control "
                "period: whether a cycle gets dearer as the run goes on.",
            )
        )
        figure_cycle_time(record, figures[-1].path)
    for i, known in enumerate(record.robot_known):
        name = f"robot_{i}"
        figures.append(
            ReportFigure(
                folder / f"exploration_robot_{i}.png",
                f"Cells {name}'s own scans mapped (its row of the coverage table).",
                wide=False,
            )
        )
        figure_robot_map(
            np.where(known, record.estimated_values, -1), record, figures[-1].path, name
        )
    return figures


def merge_figures(out_dir: Path, metrics: dict) -> list[ReportFigure]:
    """The figure of each merge (``merges/merge_<k>.png``, written with the run)."""
    unknown = metrics.get("unknown_starts") or {"merges": []}
    return [
        ReportFigure(
            Path(out_dir) / "merges" / f"merge_{k}.png",
            f"Merge {k}, at {merge['time_s']:.0f} s: both frames' maps before it and the "
            "merged map after.",
        )
        for k, merge in enumerate(unknown["merges"], start=1)
    ]


# --------------------------------------------------------------------------- html

DASH = "—"
"""What a table shows for a value the run has no number for (null in metrics.json)."""


def _cell(value: object, digits: int) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return DASH
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return html.escape(str(value))


def _table(header: list[str], rows: list[list[object]], digits: int | list[int] = 3) -> str:
    """An HTML table; ``digits`` per column (or for all) sets the decimals of floats. Columns
    of words are set left, columns of numbers right."""
    places = digits if isinstance(digits, list) else [digits] * len(header)
    words = [all(isinstance(row[k], str) for row in rows) for k in range(len(header))]

    def cell(tag: str, k: int, text: str) -> str:
        return f'<{tag} class="words">{text}</{tag}>' if words[k] else f"<{tag}>{text}</{tag}>"

    head = "".join(cell("th", k, html.escape(h)) for k, h in enumerate(header))
    body = "".join(
        "<tr>" + "".join(cell("td", k, _cell(c, places[k])) for k, c in enumerate(row)) + "</tr>"
        for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _note(text: str) -> str:
    return f'<p class="note">{html.escape(text)}</p>'


def _timing_table(metrics: dict) -> str:
    timing = metrics["timing"]
    per_robot = timing["per_robot_s"]
    table = _table(
        ["robot", "exploration time [s]"],
        [[name, t] for name, t in per_robot.items()]
        + [["total", timing["total_s"]], ["gap between first and last", timing["gap_s"]]],
        1,
    )
    if any(t is None for t in per_robot.values()):
        table += _note(
            f"{DASH}: still exploring when the run stopped ({metrics['reason']}) after "
            f"{metrics['sim_time_s']:.1f} s, so no exploration time; total and gap need every "
            "robot's."
        )
    return table


def _localization_table(metrics: dict) -> str:
    keys = ("final_dist_m", "mae_m", "rmse_m", "std_m")
    yaw_keys = ("final_yaw_rad", "mae_yaw_rad", "rmse_yaw_rad", "std_yaw_rad")
    table = _table(
        ["robot", "final error [m]", "MAE [m]", "RMSE [m]", "STD [m]",
         "final yaw error [rad]", "yaw MAE [rad]", "yaw RMSE [rad]", "yaw STD [rad]"],
        [[name, *(m[k] for k in keys + yaw_keys)] for name, m in metrics["localization"].items()],
    )  # fmt: skip
    unscored = [
        name for name in metrics["timing"]["per_robot_s"] if name not in metrics["localization"]
    ]
    if unscored:
        table += _note(
            "Not scored (no ground truth, or no estimate within its time yet: a run that "
            f"ended before the robot's first keyframe): {', '.join(unscored)}."
        )
    alignment = metrics.get("team_alignment")  # absent from runs written before it
    if alignment:
        table += _note(team_alignment_text(alignment))
    online = metrics.get("online_localization")  # absent from runs written before it
    if online:
        table += _note(
            "The pose each robot was driven and mapped by, at every control step, before any "
            "later correction (the table above scores the final estimate of the keyframes):"
        )
        table += _table(
            ["robot", "RMSE [m]", "max [m]", "yaw RMSE [rad]", "max yaw error [rad]"],
            [
                [name, m["rmse_m"], m["max_m"], m["rmse_yaw_rad"], m["max_yaw_rad"]]
                for name, m in online.items()
            ],
        )
    return table


def team_alignment_text(alignment: dict) -> str:
    """One sentence on metrics.json's ``team_alignment``: what is left of the position
    error once the whole team's map is laid onto the truth by one rigid motion."""
    return (
        f"After the one rigid motion that best lays all robots' trajectories onto the truth "
        f"(a turn of {1000 * alignment['rotation_rad']:+.1f} mrad, the team's mean position "
        f"moved {alignment['centroid_shift_m']:.3f} m), the team's position RMSE is "
        f"{alignment['aligned_rmse_m']:.3f} m: "
        "the rest of the RMSE above is the whole map turned or shifted against the start "
        "frame, not error inside it."
    )


def merge_text(merge: dict) -> str:
    """One sentence on a merge of metrics.json's ``unknown_starts``: when, which frames,
    and how far off it was at the joined frame's origin, at the robots and where it was
    made (see :func:`acslam.eval.frames.merge_metrics`)."""
    text = f"{merge['time_s']:.0f} s: {', '.join(merge['robots'])} merged into {merge['into']}"
    if merge.get("met_s") is not None:  # an older run, or no world, has none
        text += f" ({merge['time_s'] - merge['met_s']:.0f} s after the frames' robots first met)"
    if merge["error_m"] is None:
        return text + " (no ground truth to judge it)"
    text += (
        f", {merge['error_m']:.3f} m and {1000 * merge['error_rad']:.1f} mrad off at the "
        f"frame's origin{' (a false merge)' if merge['false'] else ''}, "
        f"{merge['error_at_robots_m']:.3f} m at the robots"
    )
    if merge.get("local_error_m") is None:  # too few keyframes near, or an older run
        return text + "; not judged where it was made"
    return text + (
        f"; {merge['local_error_m']:.3f} m and {1000 * merge['local_error_rad']:.1f} mrad "
        f"where it was made{' (false there too)' if merge['false_locally'] else ''}"
    )


def _merges_table(unknown: dict) -> str:
    """Every merge of frames, judged three ways (:func:`merge_text`)."""
    rows = [
        [m["time_s"], m.get("met_s"), ", ".join(m["robots"]), m["into"], m["error_m"],
         m["error_rad"], m["error_at_robots_m"], m.get("local_error_m"), m.get("local_error_rad")]
        for m in unknown["merges"]
    ]  # fmt: skip
    table = _table(
        ["time [s]", "robots first met [s]", "robots", "into", "at the origin [m]", "[rad]",
         "at the robots [m]", "where made [m]", "[rad]"],
        rows,
        [0, 0, 0, 0, 3, 4, 3, 3, 4],
    )  # fmt: skip
    left = "" if unknown["all_merged"] else f" Frames left unmerged: {unknown['frames_at_end']}."
    return table + _note(
        "A merge needs the robots to see each other: 'robots first met' is when a robot of "
        "each frame first stood within a LiDAR's reach of the other with nothing between. "
        "Each merge's error against the truth: at the joined frame's origin (a merge more "
        "than 0.3 m or 5 deg off there is a false merge), at the merged robots, and where it "
        "was made, against where both frames' own keyframes within a LiDAR's reach of the "
        "merged robots place the truth. The first two also hold the frames' drift since "
        f"their starts; the last is the merge's own error.{left}"
    )


def _combination_rows(coverage: dict) -> list[tuple[str, dict]]:
    """Table 5.3's rows: every combination of robots (the other coverage keys are areas)."""
    return [(name, c) for name, c in coverage.items() if isinstance(c, dict)]


def _coverage_table(metrics: dict) -> str:
    return _table(
        ["robots", "mapped area [m²]", "share of the team's area [%]"],
        [
            [name.replace("+", ", "), c["area_m2"], 100 * c["rate"]]
            for name, c in _combination_rows(metrics["coverage"])
        ],
        [0, 2, 1],
    ) + _note(
        "Each robot's mapped area is what its own scans made known (free or occupied); a "
        "combination's is the union of its robots' areas, its share that over the whole team's."
    )


def _explored_table(metrics: dict, record: RunRecord) -> str:
    """The explored area measured the ways the report shows it, side by side."""
    areas = explored_areas(
        record.estimated_values != UNKNOWN, record.reachable, record.spec.resolution_m**2
    )
    reachable_m2 = areas["reachable_area_m2"]

    def share(area_m2: float) -> float | None:
        return 100 * area_m2 / reachable_m2 if reachable_m2 else None

    rows = [
        ["reachable free area (true map)", reachable_m2, share(reachable_m2)],
        ["reachable free area mapped", areas["mapped_reachable_area_m2"],
         share(areas["mapped_reachable_area_m2"])],
        ["team map: all mapped cells (end of the area figure)", areas["mapped_area_m2"],
         share(areas["mapped_area_m2"])],
    ]  # fmt: skip
    combinations = _combination_rows(metrics["coverage"])
    if combinations:
        team = max(combinations, key=lambda item: item[0].count("+"))[1]["area_m2"]
        rows.append(["union of the robots' own maps (team row above)", team, share(team)])
    header = ["measure", "area [m²]", "share of the reachable free area [%]"]
    table = _table(header, rows, [0, 2, 2])
    if not reachable_m2:
        table += _note(f"{DASH}: no free area is reachable from the first start.")
    return table + _note(
        "The reachable free area is the true free space a robot can reach from the starts: "
        "what exploring must map; the run explored the share of it that is mapped. The "
        "mapped areas also count walls and free cells the LiDAR saw where no robot fits, so "
        "they can exceed it. The team map fuses every robot's scans, so a cell can be "
        "certain in it while no single robot's map is, or the other way round where robots "
        "disagree."
    )  # fmt: skip


MAPPING_NAMES = {
    "accuracy": "accuracy",
    "tpr": "true positive rate (TPR)",
    "tnr": "true negative rate (TNR)",
    "fpr": "false positive rate (FPR)",
    "fnr": "false negative rate (FNR)",
}


def _mapping_table(metrics: dict) -> str:
    mapping = metrics["mapping"]
    rows = [
        [label, None if mapping[k] is None else 100 * mapping[k]]
        for k, label in MAPPING_NAMES.items()
    ]
    aligned = mapping.get("aligned_accuracy")  # absent from older runs, None without truth
    if aligned is not None:
        rows.append(["accuracy, the map moved by the team's alignment", 100 * aligned])
    table = _table(["measure", "value [%]"], rows, [0, 1])
    scored = sum(mapping[k] for k in ("tp", "tn", "fp", "fn"))
    note = f"Over the {plural(scored, 'mapped cell')}; occupied is positive."
    if any(mapping[k] is None or not math.isfinite(mapping[k]) for k in MAPPING_NAMES):
        note += f" {DASH}: no cell of that rate's kind was mapped."
    if aligned is not None:
        note += (
            " The last row scores the map after the one rigid motion that lays the team's "
            "trajectories onto the truth (see Localization): a map turned as a whole by an "
            "early heading error scores low above however right it is inside."
        )
    return table + _note(note)


def _waste_table(metrics: dict, record: RunRecord) -> str:
    """Distance per robot and the area more than one robot mapped: what the team spent
    beyond the map (recomputed from the record, so older run folders show it too)."""
    spent = record.waste(list(metrics["timing"]["per_robot_s"]))
    rows: list[list[object]] = [[name, m, ""] for name, m in spent["travelled_m"].items()]
    rows.append(["team", spent["travelled_total_m"], spent["overlap_area_m2"]])
    table = _table(
        ["robot", "distance travelled [m]", "mapped by more than one robot [m²]"], rows, [0, 1, 1]
    )
    estimated = spent["travelled_from"] == "estimate"
    return table + _note(
        f"Overlap ratio: {100 * spent['overlap_ratio']:.1f} % of the area the robots' own "
        f"scans mapped was mapped by more than one of them. Distances along the "
        f"{spent['travelled_from']} paths"
        + (" (keyframes only, so shorter than driven)." if estimated else ".")
    )


SAFETY_NAMES = {
    "obstacle_collisions": "collisions with walls [count]",
    "robot_collisions": "collisions between robots [count]",
    "min_robot_distance_m": "closest distance between two robots [m]",
    "stuck_events": "stuck events (recovery started) [count]",
}


def _safety_table(metrics: dict) -> str:
    safety = metrics["safety"]
    table = _table(list(SAFETY_NAMES.values()), [[safety.get(key) for key in SAFETY_NAMES]], 2)
    notes = []
    if safety.get("min_robot_distance_m") is None or not math.isfinite(
        safety["min_robot_distance_m"]
    ):
        notes.append(
            f"{DASH} distance: one robot has no other to come close to."
            if metrics["robots"] == 1
            else f"{DASH} distance: no ground truth of the robots' positions to measure it on."
        )
    if safety.get("obstacle_collisions") is None:
        notes.append(f"{DASH} collisions: no ground truth to count them against.")
    return table + "".join(_note(n) for n in notes)


CYCLE_STATISTICS = ("mean", "p95", "p99", "max")


def _cycle_table(cycle_ms: dict) -> str:
    """Whole cycle and stages: mean, p95, p99, max, and p95 as a share of the control
    period (runs written before p99 and max were recorded show a dash there)."""
    period_ms = cycle_ms.get("control_period_ms")
    rows = [("cycle", cycle_ms)] + [(k, v) for k, v in cycle_ms.items() if isinstance(v, dict)]
    return _table(
        ["stage", *(f"{k} [ms]" for k in CYCLE_STATISTICS),
         f"p95 share of the control period{f' ({period_ms:g} ms)' if period_ms else ''} [%]"],
        [
            [stage_label(name), *(v.get(k) for k in CYCLE_STATISTICS),
             100 * v["p95"] / period_ms if period_ms else None]
            for name, v in rows
        ],
        [0, 1, 1, 1, 1, 0],
    )  # fmt: skip


def _patrol_table(patrol: dict) -> str:
    """Each stage's p95 at the start and the end of the patrol: flat if its cost does not
    follow the trajectory's length."""
    rows = [
        [stage_label(name), v["first_tenth_p95_ms"], v["last_tenth_p95_ms"], v["growth"]]
        for name, v in patrol["stages"].items()
    ]
    table = _table(
        ["stage", "p95, first tenth [ms]", "p95, last tenth [ms]", "last over first [ratio]"],
        rows,
        [0, 1, 1, 2],
    )
    return table + _note(
        f"After exploring, the robots drove loops through the map from "
        f"{patrol['start_s']:.0f} s to {patrol['end_s']:.0f} s: the trajectory grew while "
        "the map did not. Each figure is the stage's p95 over the first or last tenth of that."
    )


def report_tables(metrics: dict, record: RunRecord) -> dict[str, str]:
    """The run's tables in the layout of thesis Tables 5.1-5.4, as HTML, each with the
    notes that explain its dashes."""
    patrol = metrics.get("patrol")
    return {
        "Timing (Table 5.1)": _timing_table(metrics),
        "Localization (Table 5.2)": _localization_table(metrics),
        "Coverage per robot combination (Table 5.3)": _coverage_table(metrics),
        "Explored area": _explored_table(metrics, record),
        "Mapping accuracy (Table 5.4)": _mapping_table(metrics),
        "Distance and overlap": _waste_table(metrics, record),
        "Safety": _safety_table(metrics),
        "Server cycle time": _cycle_table(metrics["server_cycle_ms"]),
        **({"Server cycle over the patrol": _patrol_table(patrol)} if patrol else {}),
        **(
            {"Merges of frames (unknown starts)": _merges_table(metrics["unknown_starts"])}
            if metrics.get("unknown_starts")
            else {}
        ),
    }


def provenance_line(metrics: dict) -> str:
    """Which acslam, from which commit, with which command and when made the run."""
    made = metrics.get("provenance")
    if not made:
        return "Provenance: not recorded (a run folder written before acslam recorded it)."
    return (
        f"Made by acslam {made['acslam_version']}, commit {made['commit']}, on "
        f"{made['date_utc']} with: {made['command']}"
    )


STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1200px; padding: 0 1em;
       color: #222; line-height: 1.35; }
h1 { margin-bottom: 0.2em; }
.provenance { color: #555; font-size: 0.9em; margin-top: 0; overflow-wrap: anywhere; }
table { border-collapse: collapse; margin: 0.5em 0 0.3em 0; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: right; }
.words { text-align: left; }
th { background: #eee; }
.note { color: #444; font-size: 0.9em; margin: 0.2em 0 1em 0; max-width: 900px; }
.figures { display: flex; flex-wrap: wrap; gap: 1em 2%; align-items: flex-start; }
figure { margin: 0; flex: 0 0 100%; }
figure.half { flex: 0 0 49%; }
figure img { max-width: 100%; display: block; }
figcaption { font-size: 0.9em; margin: 0.3em 0 0.8em 0; max-width: 900px; }
"""


def write_report(out_dir: Path, record: RunRecord, metrics: dict) -> Path:
    """Write figures/ and report.html (figures embedded, so the file stands alone)."""
    out_dir = Path(out_dir)
    figures = write_figures(out_dir, record) + merge_figures(out_dir, metrics)
    status = "completed" if metrics["completed"] else f"not completed ({metrics['reason']})"
    summary = (
        f"{metrics['scenario']}: {plural(metrics['robots'], 'robot')}, planner "
        f"{metrics['planner']}, allocator {metrics['allocator']}, seed {metrics['seed']}: "
        f"{status} after {metrics['sim_time_s']:.1f} s simulated in "
        f"{metrics['wall_time_s']:.1f} s wall time ({metrics['real_time_factor']:.1f}x real "
        "time)."
    )
    sections = "".join(
        f"<h2>{html.escape(title)}</h2>{table}"
        for title, table in report_tables(metrics, record).items()
    )
    images = "".join(
        f'<figure class="{"wide" if f.wide else "half"}"><img alt="{html.escape(f.caption)}" '
        f'src="data:image/png;base64,{base64.b64encode(f.path.read_bytes()).decode()}">'
        f"<figcaption><b>Figure {n}.</b> {html.escape(f.caption)}</figcaption></figure>"
        for n, f in enumerate(figures, start=1)
    )
    title = html.escape(f"acslam run: {metrics['scenario']}")
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>{STYLE}</style></head><body>
<h1>acslam run report</h1>
<p class="provenance">{html.escape(provenance_line(metrics))}</p>
<p>{html.escape(summary)}</p>
{sections}<h2>Figures</h2><div class="figures">{images}</div>
</body></html>
"""
    return write_text(out_dir / "report.html", page)


# --------------------------------------------------------------------------- reading back

Fraction = Annotated[float, Field(ge=0, le=1)] | None
Number = Annotated[float, Field(allow_inf_nan=False)] | None


class _Section(BaseModel):
    """A part of metrics.json: the keys the report reads are checked, others kept."""

    model_config = ConfigDict(extra="allow")


class _Timing(_Section):
    per_robot_s: dict[str, Number]
    total_s: Number
    gap_s: Number


class _Localization(_Section):
    final_dist_m: float
    mae_m: float
    rmse_m: float
    std_m: float
    final_yaw_rad: float
    mae_yaw_rad: float
    rmse_yaw_rad: float
    std_yaw_rad: float
    max_m: float | None = None  # runs written before the maxima were recorded lack them
    max_yaw_rad: float | None = None


class _Coverage(_Section):
    explored_fraction_of_reachable: Fraction


class _Mapping(_Section):
    accuracy: Fraction
    aligned_accuracy: Fraction = None  # absent from runs written before it
    tpr: Fraction
    tnr: Fraction
    fpr: Fraction
    fnr: Fraction


class _CycleStatistics(_Section):
    mean: float
    p95: float
    p99: float | None = None  # runs written before p99 and max were recorded lack them
    max: float | None = None


class _Cycle(_CycleStatistics):
    control_period_ms: Annotated[float, Field(gt=0)]
    __pydantic_extra__: dict[str, _CycleStatistics]


class _Merge(_Section):
    time_s: float
    into: str
    robots: list[str]
    error_m: Number
    error_rad: Number
    error_at_robots_m: Number
    false: bool | None
    local_error_m: Number = None  # absent from runs written before it
    local_error_rad: Number = None
    false_locally: bool | None = None
    met_s: Number = None


class _UnknownStarts(_Section):
    merges: list[_Merge]
    all_merged: bool
    frames_at_end: list[str]


class ReportedMetrics(_Section):
    """What the report reads of ``metrics.json``."""

    scenario: str
    robots: Annotated[int, Field(ge=1)]
    seed: int
    planner: str
    allocator: str
    completed: bool
    reason: str
    sim_time_s: float
    wall_time_s: float
    real_time_factor: float
    timing: _Timing
    localization: dict[str, _Localization]
    online_localization: dict[str, _Localization] | None = None  # absent from older runs
    coverage: _Coverage
    mapping: _Mapping
    safety: dict[str, float | None]  # infinite in runs written before JSON was strict
    server_cycle_ms: _Cycle
    unknown_starts: _UnknownStarts | None = None  # runs with known starts have none


def read_run(out_dir: Path) -> tuple[dict, RunRecord]:
    """A run folder's metrics (checked as :class:`ReportedMetrics`) and run record, or
    one error naming the file and the field."""
    out_dir = Path(out_dir)
    metrics_path = out_dir / "metrics.json"
    if not metrics_path.is_file():
        raise DataError(metrics_path, "not found: is this a run folder?")
    metrics = read_json(metrics_path, "run's metrics")
    if not isinstance(metrics, dict):
        raise DataError(metrics_path, "the run's metrics must be a JSON object")
    validated(ReportedMetrics, metrics, metrics_path)
    return metrics, RunRecord.load(out_dir / "run.npz")


def rebuild_report(out_dir: Path) -> Path:
    """Re-make figures and report.html of a finished run from its saved files, both read
    and checked before anything is written."""
    metrics, record = read_run(out_dir)
    return write_report(out_dir, record, metrics)
