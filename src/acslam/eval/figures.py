"""Figures drawn from ground truth and run outputs (matplotlib lives only under acslam.eval)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from acslam.eval.plotting import plt, save_figure
from acslam.worlds.world import World

ROBOT_COLOURS = (
    "tab:red",
    "tab:orange",
    "gold",
    "tab:purple",
    "tab:cyan",
    "tab:pink",
    "tab:brown",
    "tab:olive",
    "tab:green",
    "tab:gray",
)


def robot_colour(robot_id: int) -> str:
    """The thesis draws robot_0, 1, 2 in red, orange and yellow; later ones cycle on."""
    return ROBOT_COLOURS[robot_id % len(ROBOT_COLOURS)]


def _crop_to_free(world: World, margin_m: float = 1.0) -> tuple[float, float, float, float]:
    rows, cols = np.nonzero(world.free)
    spec = world.spec
    if len(rows) == 0:
        return (
            spec.origin_x_m,
            spec.origin_x_m + spec.width_m,
            spec.origin_y_m,
            spec.origin_y_m + spec.height_m,
        )
    x0 = spec.origin_x_m + cols.min() * spec.resolution_m - margin_m
    x1 = spec.origin_x_m + (cols.max() + 1) * spec.resolution_m + margin_m
    y0 = spec.origin_y_m + rows.min() * spec.resolution_m - margin_m
    y1 = spec.origin_y_m + (rows.max() + 1) * spec.resolution_m + margin_m
    return x0, x1, y0, y1


def plot_world(
    world: World,
    starts: np.ndarray,
    landmarks: np.ndarray,
    path: Path,
    trajectories: list[np.ndarray] | None = None,
) -> None:
    """The map with start poses (arrows), landmarks and optional (T, 3) trajectories."""
    spec = world.spec
    extent = (
        spec.origin_x_m,
        spec.origin_x_m + spec.width_m,
        spec.origin_y_m,
        spec.origin_y_m + spec.height_m,
    )
    fig, ax = plt.subplots(figsize=(8, 8), dpi=120)
    ax.imshow(
        world.free,
        cmap="gray",
        origin="lower",
        extent=extent,
        vmin=0,
        vmax=1,
        interpolation="nearest",
    )
    if len(landmarks):
        ax.scatter(landmarks[:, 0], landmarks[:, 1], s=6, c="tab:blue", label="landmarks")
    for i, trajectory in enumerate(trajectories or []):
        ax.plot(trajectory[:, 0], trajectory[:, 1], lw=1.0, color=robot_colour(i))
    for i, (x, y, theta) in enumerate(starts):
        ax.plot(x, y, "o", ms=6, color=robot_colour(i), mec="k", label=f"robot_{i} start")
        ax.arrow(
            x,
            y,
            0.4 * np.cos(theta),
            0.4 * np.sin(theta),
            width=0.04,
            color=robot_colour(i),
            length_includes_head=True,
        )
    x0, x1, y0, y1 = _crop_to_free(world)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(world.name)
    ax.legend(loc="upper right", fontsize=7)
    save_figure(fig, path)
