"""UTIAS MRCLAM reader: 5 robots' logs -> time-ordered acslam messages + separate truth.

Files (see the dataset's PROVENANCE.md): ``RobotN_Odometry.dat`` (t, v, w),
``RobotN_Measurement.dat`` (t, barcode, range, bearing), ``RobotN_Groundtruth.dat``
(t, x, y, theta), ``Landmark_Groundtruth.dat`` and ``Barcodes.dat``. Robot N keeps id N.

* Odometry: each sample (v, w) is held until the next sample's time and integrated
  exactly along the arc, giving one :class:`OdometryIncrement` per sample interval.
* Measurements at the same time by the same robot form one
  :class:`LandmarkObservations` with points ``(r cos b, r sin b, 0)``. Their identities
  (subject numbers, from the barcodes) travel only in the side channel
  :attr:`MrclamData.point_subjects`, for evaluation; measurements of other robots
  (subjects 1-5) are kept apart in :attr:`MrclamData.robot_measurements`.

Bad input, decided per field: a line with the wrong number of columns, a non-number or a
non-finite value is a :class:`DataError` naming the file and line (the file is corrupt),
and so is a missing file, or a robot with fewer than two odometry records or no ground
truth (nothing to run it on).
Values that are well-formed but unusable are skipped and counted in
:attr:`MrclamData.skipped`: a barcode not in ``Barcodes.dat`` (the dataset's known
spurious readings), a non-positive range, and an odometry/ground-truth sample whose time
does not advance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from acslam.errors import DataError
from acslam.messages import LandmarkObservations, OdometryIncrement

ROBOT_IDS = (1, 2, 3, 4, 5)


@dataclass
class MrclamData:
    """Messages in time order plus everything that must not reach the server."""

    messages: list[OdometryIncrement | LandmarkObservations]
    point_subjects: dict[int, np.ndarray]
    """Message index -> true subject id of each point (evaluation side channel)."""
    robot_measurements: np.ndarray
    """(K, 5): time, observing robot, observed robot, range, bearing."""
    groundtruth: dict[int, tuple[np.ndarray, np.ndarray]]
    """Robot id -> (N,) stamps and (N, 3) poses, angles unwrapped."""
    landmark_truth: dict[int, np.ndarray]
    """Landmark subject id -> (2,) position."""
    skipped: dict[str, int] = field(default_factory=dict)


def read_table(path: Path, columns: int) -> np.ndarray:
    """A whitespace table with ``#`` comments; malformed lines raise DataError with line."""
    if not path.is_file():
        raise DataError(path, "file not found")
    rows = []
    with path.open(encoding="utf-8", errors="replace") as handle:
        for number, line in enumerate(handle, start=1):
            text = line.split("#", 1)[0].strip()
            if not text:
                continue
            parts = text.split()
            if len(parts) != columns:
                raise DataError(path, f"expected {columns} columns, got {len(parts)}", number)
            try:
                values = [float(p) for p in parts]
            except ValueError:
                raise DataError(path, f"not a number in {text!r}", number) from None
            if not all(math.isfinite(v) for v in values):
                raise DataError(path, f"non-finite value in {text!r}", number)
            rows.append(values)
    return np.array(rows, dtype=float).reshape(-1, columns)


def _advancing(table: np.ndarray) -> tuple[np.ndarray, int]:
    """Rows whose time strictly increases over the last kept row; and how many were dropped."""
    keep = np.ones(len(table), dtype=bool)
    last = -math.inf
    for i, t in enumerate(table[:, 0]):
        if t <= last:
            keep[i] = False
        else:
            last = t
    return table[keep], int((~keep).sum())


def integrate_arc(v: float, w: float, dt: float) -> tuple[float, float, float]:
    """End pose of constant (v, w) for dt, in the start frame."""
    dtheta = w * dt
    if abs(dtheta) < 1e-9:
        return v * dt, 0.0, dtheta
    radius = v / w
    return radius * math.sin(dtheta), radius * (1.0 - math.cos(dtheta)), dtheta


def read_mrclam(folder: str | Path, max_time_s: float | None = None) -> MrclamData:
    """Read a MRCLAM dataset folder; keep ``max_time_s`` seconds after the first odometry."""
    folder = Path(folder)
    skipped = {"unknown_barcode": 0, "bad_range": 0, "time_not_advancing": 0}
    barcodes = read_table(folder / "Barcodes.dat", 2)
    barcode_to_subject = {int(b): int(s) for s, b in barcodes}
    landmark_table = read_table(folder / "Landmark_Groundtruth.dat", 5)
    landmark_truth = {int(row[0]): row[1:3].copy() for row in landmark_table}

    odometry, measurements, groundtruth = {}, {}, {}
    for robot in ROBOT_IDS:
        odometry_path = folder / f"Robot{robot}_Odometry.dat"
        odometry[robot], dropped = _advancing(read_table(odometry_path, 3))
        if len(odometry[robot]) < 2:
            raise DataError(odometry_path, "fewer than two odometry records: robot cannot move")
        skipped["time_not_advancing"] += dropped
        gt_path = folder / f"Robot{robot}_Groundtruth.dat"
        gt, dropped = _advancing(read_table(gt_path, 4))
        if len(gt) == 0:
            raise DataError(gt_path, "no ground-truth records: the start pose is unknown")
        skipped["time_not_advancing"] += dropped
        groundtruth[robot] = (gt[:, 0], np.column_stack([gt[:, 1:3], np.unwrap(gt[:, 3])]))
        measurements[robot] = read_table(folder / f"Robot{robot}_Measurement.dat", 4)

    t0 = min(table[0, 0] for table in odometry.values())
    t_end = math.inf if max_time_s is None else t0 + max_time_s

    events: list[tuple[float, int, int, object]] = []  # (stamp, order, robot, payload)
    robot_rows = []
    for robot in ROBOT_IDS:
        table = odometry[robot]
        for (t, v, w), t_next in zip(table[:-1], table[1:, 0], strict=True):
            if t_next > t_end:
                break
            dx, dy, dth = integrate_arc(v, w, t_next - t)
            events.append((t_next, 0, robot, OdometryIncrement(robot, t_next, t, dx, dy, dth)))
        groups: dict[float, list[tuple[int, float, float]]] = {}
        for t, barcode, rng, bearing in measurements[robot]:
            if t > t_end:
                continue
            subject = barcode_to_subject.get(int(barcode))
            if subject is None:
                skipped["unknown_barcode"] += 1
            elif rng <= 0:
                skipped["bad_range"] += 1
            elif subject in ROBOT_IDS:
                robot_rows.append((t, robot, subject, rng, bearing))
            else:
                groups.setdefault(t, []).append((subject, rng, bearing))
        for t, items in groups.items():
            subjects = np.array([s for s, _, _ in items])
            points = np.array([[r * math.cos(b), r * math.sin(b), 0.0] for _, r, b in items])
            events.append((t, 1, robot, (LandmarkObservations(robot, t, points), subjects)))
    events.sort(key=lambda e: (e[0], e[1], e[2]))

    messages: list[OdometryIncrement | LandmarkObservations] = []
    point_subjects: dict[int, np.ndarray] = {}
    for _, _, _, payload in events:
        if isinstance(payload, tuple):
            point_subjects[len(messages)] = payload[1]
            messages.append(payload[0])
        else:
            messages.append(payload)
    return MrclamData(
        messages,
        point_subjects,
        np.array(robot_rows, dtype=float).reshape(-1, 5),
        groundtruth,
        landmark_truth,
        skipped,
    )
