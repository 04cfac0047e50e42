"""CARMEN laser logs (``.clf``/``.log``, plain, ``.bz2`` or ``.gz``), e.g. Intel Lab, fr079.

Only ``ODOM`` and ``FLASER`` lines are read; other messages (``PARAM``, ``SYNC``, comments)
are ignored. Messages are not logged in time order (the Intel log steps back in time, by
up to 0.6 s, about 600 times per message type), so records are sorted by logger timestamp.
Real logs can also contain truncated lines, so a malformed ``ODOM``/``FLASER`` line, or a
line that is not ASCII text (as the format is), is skipped and recorded with its line
number rather than aborting the whole log, with one warning per kind of problem giving
the count and the first line numbers; a file that cannot be read at all raises
:class:`DataError`.

Line formats (whitespace separated; timestamps are the last three fields):

- ``ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp``
- ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname
  logger_timestamp``, ``x y theta`` being the laser pose.
"""

from __future__ import annotations

import bz2
import gzip
import math
import warnings
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from acslam.errors import AcslamWarning, DataError
from acslam.geometry import between

NO_RETURN_RANGE_M = 50.0
"""SICK logs report "no return" as ~80 m; readings at or above this become ``inf``."""

_ODOM_FIELDS = 10
_FLASER_FIXED_FIELDS = 11  # tag, n, 6 pose values, 3 timestamp fields
_LINES_NAMED = 5  # line numbers a warning lists


class CarmenWarning(AcslamWarning):
    """Lines of a CARMEN log were skipped."""


@dataclass(frozen=True)
class OdometryRecord:
    """Raw wheel odometry pose (odometry frame) and velocities; ``line`` is 1-based.

    ``stamp_s`` is the logger timestamp (the order records are replayed in),
    ``ipc_stamp_s`` the message's own (first trailing) timestamp, by which evaluation
    tools and reference relations name a message.
    """

    stamp_s: float
    pose_xytheta: np.ndarray
    velocity_mps: float
    yaw_rate_radps: float
    line: int
    ipc_stamp_s: float


@dataclass(frozen=True)
class LaserRecord:
    """One front-laser sweep: ranges (m, ``inf`` = no return) at ``angles_rad`` in the
    laser frame, the laser pose and the robot odometry pose (odometry frame). Stamps as
    in :class:`OdometryRecord`."""

    stamp_s: float
    angles_rad: np.ndarray
    ranges_m: np.ndarray
    laser_pose_xytheta: np.ndarray
    odom_pose_xytheta: np.ndarray
    line: int
    ipc_stamp_s: float


@dataclass
class CarmenLog:
    """Records sorted by logger timestamp (stable, so ties keep file order)."""

    path: Path
    odometry: list[OdometryRecord] = field(default_factory=list)
    scans: list[LaserRecord] = field(default_factory=list)
    skipped_lines: list[tuple[int, str]] = field(default_factory=list)

    @property
    def records(self) -> list[OdometryRecord | LaserRecord]:
        """Odometry and laser records merged in time order."""
        merged: list[OdometryRecord | LaserRecord] = [*self.odometry, *self.scans]
        merged.sort(key=lambda record: (record.stamp_s, record.line))
        return merged


def laser_offset(log: CarmenLog) -> np.ndarray:
    """The laser pose in the robot frame: the median of ``odom^-1 * laser`` over the scans."""
    offsets = np.array(
        [between(s.odom_pose_xytheta, s.laser_pose_xytheta) for s in log.scans], dtype=float
    )
    return np.median(offsets, axis=0)


def _floats(tokens: list[str]) -> np.ndarray:
    values = np.asarray(tokens, dtype=np.float64)
    if not np.isfinite(values).all():
        raise ValueError("non-finite value")
    return values


def _parse_odom(tokens: list[str], line: int) -> OdometryRecord:
    if len(tokens) != _ODOM_FIELDS:
        raise ValueError(f"expected {_ODOM_FIELDS} fields, got {len(tokens)}")
    values = _floats(tokens[1:8] + tokens[9:10])
    return OdometryRecord(values[7], values[0:3], values[3], values[4], line, values[6])


def _parse_flaser(tokens: list[str], line: int, fov_rad: float) -> LaserRecord:
    if len(tokens) < 2 or not tokens[1].isdigit():
        raise ValueError("missing or non-integer beam count")
    n = int(tokens[1])
    if n < 1 or len(tokens) != n + _FLASER_FIXED_FIELDS:
        raise ValueError(f"expected {n + _FLASER_FIXED_FIELDS} fields, got {len(tokens)}")
    ranges = _floats(tokens[2 : 2 + n])
    if (ranges < 0).any():
        raise ValueError("negative range")
    poses = _floats(tokens[2 + n : 8 + n])
    ipc_stamp, stamp = _floats([tokens[8 + n], tokens[10 + n]])
    ranges[ranges >= NO_RETURN_RANGE_M] = np.inf
    angles = np.linspace(-fov_rad / 2, fov_rad / 2, n) if n > 1 else np.zeros(1)
    return LaserRecord(stamp, angles, ranges, poses[0:3], poses[3:6], line, ipc_stamp)


def _read_lines(path: Path) -> list[bytes]:
    """The file's lines, undecoded: each is checked for ASCII on its own."""
    try:
        if path.name.endswith((".bz2", ".gz")):
            opener = bz2.open if path.name.endswith(".bz2") else gzip.open
            with opener(path, "rb") as stream:
                return stream.read().splitlines()
        return path.read_bytes().splitlines()
    except FileNotFoundError:
        raise DataError(path, "log file not found") from None
    except IsADirectoryError:
        raise DataError(path, "is a folder, not a log file") from None
    except (OSError, EOFError) as exc:
        raise DataError(path, f"cannot read log ({type(exc).__name__}: {exc})") from None


def _warn_skipped(path: Path, skipped: list[tuple[int, str]]) -> None:
    """One warning per kind of problem: the count and the first line numbers."""
    lines_by_problem: dict[str, list[int]] = defaultdict(list)
    for number, problem in skipped:
        lines_by_problem[problem].append(number)
    for problem, numbers in lines_by_problem.items():
        message = f"{path}:{numbers[0]}: skipped {problem}"
        if len(numbers) > 1:
            named = ", ".join(str(n) for n in numbers[:_LINES_NAMED])
            more = ", ..." if len(numbers) > _LINES_NAMED else ""
            message += f" ({len(numbers)} lines: {named}{more})"
        warnings.warn(message, CarmenWarning, stacklevel=3)


def read_carmen(path: str | Path, fov_rad: float = math.pi) -> CarmenLog:
    """Read ODOM and FLASER records of a CARMEN log, skipping (and warning about)
    malformed lines. ``fov_rad``: the laser's field of view, first beam at -fov/2."""
    path = Path(path)
    log = CarmenLog(path)
    for number, raw in enumerate(_read_lines(path), start=1):
        if not raw.isascii():
            log.skipped_lines.append((number, "non-ASCII line"))
            continue
        tokens = raw.decode("ascii").split()
        if not tokens or tokens[0] not in ("ODOM", "FLASER"):
            continue
        try:
            if tokens[0] == "ODOM":
                log.odometry.append(_parse_odom(tokens, number))
            else:
                log.scans.append(_parse_flaser(tokens, number, fov_rad))
        except ValueError as exc:
            log.skipped_lines.append((number, f"{tokens[0]}: {exc}"))
    _warn_skipped(path, log.skipped_lines)
    log.odometry.sort(key=lambda record: record.stamp_s)
    log.scans.sort(key=lambda record: record.stamp_s)
    return log
