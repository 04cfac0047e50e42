"""CARMEN log reader on the real Intel Lab and Freiburg 079 logs and on a garbled log."""

from __future__ import annotations

import bz2
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from acslam.datasets.carmen import CarmenWarning, LaserRecord, read_carmen
from acslam.errors import DataError


@pytest.mark.parametrize(
    ("relpath", "odometry", "scans", "beams"),
    [
        ("datasets/intel_lab_carmen/intel.clf.bz2", 26915, 13631, 180),
        ("datasets/fr079_carmen/fr079.clf.bz2", 8951, 4934, 360),
        ("datasets/intel_lab_carmen/intel-corrected.log.gz", 14541, 910, 180),
    ],
)
def test_real_logs(
    shared_dataset: Callable[[str], Path], relpath: str, odometry: int, scans: int, beams: int
) -> None:
    log = read_carmen(shared_dataset(relpath))
    assert (len(log.odometry), len(log.scans), log.skipped_lines) == (odometry, scans, [])
    stamps = [record.stamp_s for record in log.records]
    assert len(stamps) == odometry + scans
    assert (np.diff(stamps) >= 0).all()
    scan = log.scans[0]
    assert scan.ranges_m.shape == scan.angles_rad.shape == (beams,)
    assert scan.angles_rad[0] == pytest.approx(-np.pi / 2) and scan.angles_rad[-1] == pytest.approx(
        np.pi / 2
    )
    all_ranges = np.concatenate([s.ranges_m for s in log.scans])
    assert np.isinf(all_ranges).any() and np.nanmax(all_ranges[np.isfinite(all_ranges)]) < 50.0


def _flaser(stamp: float, n: int = 3) -> str:
    ranges = " ".join(["1.5"] * n)
    return f"FLASER {n} {ranges} 1 2 0.5 1 2 0.5 100.0 host {stamp}"


def test_garbled_lines_are_skipped_counted_and_named(tmp_path: Path) -> None:
    lines = [
        "# comment",
        "PARAM robot_front_laser_max 80.99 1 host 0",
        "ODOM 0 0 0 0 0 0 100.0 host 0.5",
        _flaser(0.2),
        "ODOM 0 0 0 0 0 0 100.0 host",  # 5: truncated
        _flaser(0.3)[:-12],  # 6: truncated
        _flaser(0.4).replace("1.5", "x.5", 1),  # 7: non-numeric range
        "FLASER three 1 1 1",  # 8: bad count
        "ODOM 1 1 nan 0 0 0 100.0 host 0.9",  # 9: NaN
        _flaser(0.1),
    ]
    path = tmp_path / "garbled.clf.bz2"
    path.write_bytes(bz2.compress(("\n".join(lines) + "\n").encode()))
    with pytest.warns(CarmenWarning) as caught:
        log = read_carmen(path)
    assert [number for number, _ in log.skipped_lines] == [5, 6, 7, 8, 9]
    assert [str(w.message).split(": ")[0] for w in caught] == [
        f"{path}:{n}" for n in (5, 6, 7, 8, 9)
    ]
    assert len(log.odometry) == 1 and len(log.scans) == 2
    assert [(type(r), r.line) for r in log.records] == [
        (LaserRecord, 10),
        (LaserRecord, 4),
        (type(log.odometry[0]), 3),
    ]
    assert log.scans[0].laser_pose_xytheta.tolist() == [1.0, 2.0, 0.5]
    # The ipc (first trailing) stamp is kept beside the logger stamp the records sort by.
    assert [(r.ipc_stamp_s, r.stamp_s) for r in log.records] == [
        (100.0, 0.1),
        (100.0, 0.2),
        (100.0, 0.5),
    ]


def test_unreadable_files_raise_data_error(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="not found"):
        read_carmen(tmp_path / "missing.clf")
    broken = tmp_path / "broken.clf.bz2"
    broken.write_bytes(b"BZh9 this is not bzip2")
    with pytest.raises(DataError, match="cannot read"):
        read_carmen(broken)
    binary = tmp_path / "binary.clf"
    binary.write_bytes(b"\xff\xfe\x00ODOM")
    # Not ASCII, so not a CARMEN line: skipped and counted like any other malformed line.
    with pytest.warns(CarmenWarning, match=r"binary\.clf:1: skipped non-ASCII line$"):
        log = read_carmen(binary)
    assert log.skipped_lines == [(1, "non-ASCII line")] and not log.records
