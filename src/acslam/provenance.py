"""What produced a result: acslam's version, the source commit, the command line and the
date, recorded in ``metrics.json`` and shown in reports so a figure can be traced back."""

from __future__ import annotations

import shlex
import subprocess
import sys
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from acslam.files import strict_json, write_json

UNKNOWN = "unknown"
SOURCE_ROOT = Path(__file__).resolve().parents[2]
"""The checkout acslam runs from (``src/acslam`` lives two levels below it)."""
GIT_TIMEOUT_S = 5.0


def provenance() -> dict[str, str]:
    """``acslam_version``, ``commit`` (``-dirty`` with uncommitted changes to tracked
    files, ``unknown`` outside a git checkout of acslam), ``command`` and ``date_utc``."""
    return {
        "acslam_version": _version(),
        "commit": _commit(),
        "command": command_line(),
        "date_utc": datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
    }


def write_metrics(out_dir: Path, metrics: dict) -> dict:
    """Write ``out_dir/metrics.json`` with its provenance, as strict JSON; returns the
    metrics as written (a figure without a value is None, JSON's ``null``)."""
    written = strict_json({**metrics, "provenance": provenance()})
    write_json(Path(out_dir) / "metrics.json", written)
    return written


CLI_MODULE = Path(__file__).resolve().with_name("cli.py")


def command_line() -> str:
    """This process's command line as a shell would take it, the program named ``acslam``
    whether it was started by its script or by ``python -m acslam.cli``."""
    program = sys.argv[0] if sys.argv else ""
    if Path(program).name == "acslam" or (program and Path(program).resolve() == CLI_MODULE):
        program = "acslam"
    return shlex.join([program, *sys.argv[1:]])


def _version() -> str:
    try:
        return version("acslam")
    except PackageNotFoundError:
        return UNKNOWN


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(
            ["git", "-C", str(SOURCE_ROOT), *args],
            capture_output=True,
            text=True,
            timeout=GIT_TIMEOUT_S,
            check=False,
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def _commit() -> str:
    """The checkout's HEAD, only if acslam's own sources are its top level: an installed
    copy inside some other repository must not report that repository's commit."""
    top = _git("rev-parse", "--show-toplevel")
    if top is None or Path(top).resolve() != SOURCE_ROOT:
        return UNKNOWN
    head = _git("rev-parse", "HEAD")
    if head is None:
        return UNKNOWN
    changes = _git("status", "--porcelain", "--untracked-files=no")
    return f"{head}-dirty" if changes else head
