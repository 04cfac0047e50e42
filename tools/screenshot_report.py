"""Render a run's ``report.html`` to a PNG in headless Chromium, as a reader sees it.

``python tools/screenshot_report.py RUN/report.html OUT.png [--width 1400]``

Needs a Chromium (Debian: ``apt-get install chromium``); it is not an acslam dependency.
The page is drawn in a window taller than any report and the blank rest is cut off.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
WINDOW_HEIGHT_PX = 16000
"""Taller than a report of ten robots; what is left blank below the page is cropped."""
BOTTOM_MARGIN_PX = 24
TIMEOUT_S = 120.0


def find_browser() -> str:
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    sys.exit("screenshot_report: no Chromium found (Debian: apt-get install chromium)")


def screenshot(page: Path, out: Path, width_px: int) -> Path:
    """Draw ``page`` ``width_px`` wide into ``out``, cropped below the last content."""
    with tempfile.TemporaryDirectory(prefix="acslam-chromium-") as profile:
        # A fresh profile and no background traffic: the same picture on any machine.
        command = [
            find_browser(),
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            f"--user-data-dir={profile}",
            f"--screenshot={out}",
            f"--window-size={width_px},{WINDOW_HEIGHT_PX}",
            page.resolve().as_uri(),
        ]
        done = subprocess.run(command, capture_output=True, text=True, timeout=TIMEOUT_S)
    if done.returncode != 0 or not out.is_file():
        sys.exit(f"screenshot_report: chromium failed ({done.returncode}): {done.stderr[-500:]}")
    with Image.open(out) as image:
        pixels = np.asarray(image.convert("L"))
        background = pixels[-1, 0]
        drawn = np.nonzero((pixels != background).any(axis=1))[0]
        bottom = min(len(pixels), (drawn[-1] + 1 if len(drawn) else 1) + BOTTOM_MARGIN_PX)
        image.crop((0, 0, image.width, bottom)).save(out)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page", type=Path, help="a report.html")
    parser.add_argument("out", type=Path, help="the PNG to write")
    parser.add_argument("--width", type=int, default=1400, help="window width in pixels")
    args = parser.parse_args()
    if not args.page.is_file():
        sys.exit(f"screenshot_report: {args.page}: no such file")
    print(screenshot(args.page, args.out, args.width))


if __name__ == "__main__":
    main()
