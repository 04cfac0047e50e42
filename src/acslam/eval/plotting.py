"""matplotlib, set up once for files: the non-interactive Agg backend, chosen before
pyplot is first imported, so figures render on machines without a display.
Every figure module of acslam imports ``plt`` from here and saves through
:func:`save_figure`."""

from pathlib import Path
from typing import Any

import matplotlib

from acslam.files import atomic_path

matplotlib.use("Agg")
import matplotlib.pyplot as plt

__all__ = ["plt", "save_figure"]


def save_figure(fig: plt.Figure, path: Path, **savefig_options: Any) -> Path:
    """Write ``fig`` to ``path`` atomically (its format from the suffix) and close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(path) as temporary:
            fig.savefig(temporary, **savefig_options)
    finally:
        plt.close(fig)
    return path
