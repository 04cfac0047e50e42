"""Figures of SLAM runs on logged datasets (matplotlib lives only under acslam.eval)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from acslam.eval.figures import robot_colour
from acslam.eval.plotting import plt, save_figure
from acslam.grid import FREE, OCCUPIED, GridSpec


def plot_slam_run(
    path: Path,
    truth: dict[int, np.ndarray],
    slam: dict[int, np.ndarray],
    dead_reckoning: dict[int, np.ndarray],
    landmark_truth: np.ndarray,
    landmark_estimate: np.ndarray,
    title: str,
) -> None:
    """Trajectories ((N, 3) per robot: truth solid thin, SLAM solid, dead reckoning dashed)
    and landmarks (truth crosses, estimates circles) on one top-down plot."""
    fig, ax = plt.subplots(figsize=(9, 7))
    for robot in sorted(truth):
        colour = robot_colour(robot)
        ax.plot(*truth[robot][:, :2].T, color="0.6", lw=0.6)
        ax.plot(*dead_reckoning[robot][:, :2].T, color=colour, lw=0.8, ls="--", alpha=0.6)
        ax.plot(*slam[robot][:, :2].T, color=colour, lw=1.2, label=f"robot {robot}")
    if len(landmark_truth):
        ax.plot(*landmark_truth[:, :2].T, "kx", ms=8, label="landmark truth")
    if len(landmark_estimate):
        ax.plot(*landmark_estimate[:, :2].T, "o", mfc="none", mec="k", ms=6, label="estimate")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    save_figure(fig, path, dpi=120)


def plot_track_panels(
    path: Path, panels: list[tuple[dict[int, np.ndarray], np.ndarray, str]]
) -> None:
    """Side by side, each panel's trajectories ((N, 3) per robot) and landmarks (circles)
    in its own frame, with its title: a merge of frames, before and after."""
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 5), squeeze=False)
    for ax, (tracks, landmarks, title) in zip(axes[0], panels, strict=True):
        for robot, poses in sorted(tracks.items()):
            ax.plot(*poses[:, :2].T, color=robot_colour(robot), lw=1.0, label=f"robot {robot}")
            ax.plot(*poses[0, :2], "o", color=robot_colour(robot), ms=4)
        if len(landmarks):
            ax.plot(*landmarks[:, :2].T, "o", mfc="none", mec="k", ms=5, label="landmarks")
        ax.set_aspect("equal")
        ax.set_title(title, fontsize=9)
        ax.legend(loc="best", fontsize=7)
    save_figure(fig, path, dpi=100)


def _grid_image(values: np.ndarray) -> np.ndarray:
    return np.select([values == OCCUPIED, values == FREE], [0.0, 1.0], default=0.75)


def _draw_map(
    ax: plt.Axes, values: np.ndarray, spec: GridSpec, tracks: Sequence[np.ndarray], title: str
) -> None:
    ax.imshow(
        _grid_image(values), cmap="gray", origin="lower", extent=spec.extent_m, vmin=0, vmax=1
    )
    for robot, track in enumerate(tracks):
        ax.plot(track[:, 0], track[:, 1], lw=0.3, color=robot_colour(robot), alpha=0.6)
    ax.set(title=title, xlabel="x [m]", ylabel="y [m]")


def plot_map(
    path: Path, values: np.ndarray, spec: GridSpec, tracks: Sequence[np.ndarray], title: str
) -> None:
    """One occupancy map with each robot's trajectory ((N, 3)) over it."""
    fig, ax = plt.subplots(figsize=(9, 9))
    _draw_map(ax, values, spec, tracks, title)
    save_figure(fig, path, dpi=200)


def plot_map_panels(
    path: Path,
    panels: list[tuple[np.ndarray, GridSpec, Sequence[np.ndarray], str]],
) -> None:
    """Maps side by side, each ``(values, spec, tracks, title)``."""
    fig, axes = plt.subplots(1, len(panels), figsize=(8 * len(panels), 8))
    for ax, panel in zip(axes, panels, strict=True):
        _draw_map(ax, *panel)
    save_figure(fig, path, dpi=150)
