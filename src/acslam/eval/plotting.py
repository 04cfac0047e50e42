"""matplotlib, set up once for files: the non-interactive Agg backend, chosen before
pyplot is first imported, so figures render on machines without a display.
Every figure module of acslam imports ``plt`` from here and writes through
:func:`save_figure`."""

from pathlib import Path

import matplotlib

from acslam.files import atomic_path

matplotlib.use("Agg")
import matplotlib.pyplot as plt

__all__ = ["plt", "save_figure"]

CROP_MARGIN_IN = 0.05
"""Blank margin kept around what a figure draws, in inches."""


def save_figure(fig: plt.Figure, path: Path, *, dpi: float | None = None) -> Path:
    """Write ``fig`` atomically as an image cropped to what it draws, then free it.

    A canvas is sized before equal-aspect axes shrink into it, so a map of a long
    corridor would otherwise sit in a band of blank paper; cropping also takes in a
    colour key placed beside the axes. ``dpi`` defaults to the figure's own.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(path) as temporary:
            fig.savefig(
                temporary, dpi=dpi or "figure", bbox_inches="tight", pad_inches=CROP_MARGIN_IN
            )
    finally:
        plt.close(fig)
    return path
