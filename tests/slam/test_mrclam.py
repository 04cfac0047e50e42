"""MRCLAM reader and evaluation on a short prefix of the real dataset 7."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from acslam.datasets.mrclam import integrate_arc, read_mrclam, read_table
from acslam.errors import DataError
from acslam.messages import LandmarkObservations
from acslam.slam.mrclam_eval import pairwise_precision_recall, run_mrclam

DATASET = "datasets/mrclam_dataset7"


def test_arc_integration() -> None:
    np.testing.assert_allclose(integrate_arc(1.0, 0.0, 2.0), (2.0, 0.0, 0.0))
    # Quarter circle of radius 1: ends at (1, 1) turned by pi/2.
    np.testing.assert_allclose(integrate_arc(np.pi / 2, np.pi / 2, 1.0), (1.0, 1.0, np.pi / 2))


def test_malformed_line_names_file_and_line(tmp_path: Path) -> None:
    path = tmp_path / "Robot1_Odometry.dat"
    path.write_text("# header\n1.0 0.1 0.0\n2.0 zero 0.0\n")
    with pytest.raises(DataError, match=r"Robot1_Odometry.dat:3: not a number"):
        read_table(path, 3)
    path.write_text("1.0 0.1\n")
    with pytest.raises(DataError, match=r":1: expected 3 columns"):
        read_table(path, 3)


def test_pairwise_precision_recall() -> None:
    truth = np.array([1, 1, 1, 2, 2])
    est = np.array([0, 0, 1, 1, 1])  # one split of landmark 1, one merge of 1 with 2
    precision, recall = pairwise_precision_recall(truth, est)
    assert precision == pytest.approx(2 / 4)  # pairs on one estimate: 1 + 3, true: 1 + 1
    assert recall == pytest.approx(2 / 4)  # true pairs: 3 + 1, kept together: 1 + 1


def test_reader_keeps_identities_out_of_the_messages(shared_dataset: Callable) -> None:
    data = read_mrclam(shared_dataset(DATASET), max_time_s=30.0)
    stamps = [m.stamp for m in data.messages]
    assert stamps == sorted(stamps)
    observations = [m for m in data.messages if isinstance(m, LandmarkObservations)]
    assert observations and all(m.descriptors is None for m in observations)
    subjects = np.concatenate(list(data.point_subjects.values()))
    assert set(subjects) <= set(range(6, 21))
    assert set(data.robot_measurements[:, 2]) <= {1, 2, 3, 4, 5}


def test_slam_beats_dead_reckoning_on_the_first_120_s(
    shared_dataset: Callable, tmp_path: Path
) -> None:
    """Known-association reference on 120 s: measured overall RMSE 0.15 m vs 0.48 m dead
    reckoning. Bounds: overall <= 0.2 m and better than dead reckoning for every robot; the
    first two minutes are mostly short drives, so odometry has not drifted far yet and a
    5x factor is not reachable on the prefix."""
    metrics = run_mrclam(shared_dataset(DATASET), tmp_path, known_association=True, max_time_s=120)
    assert metrics["overall"]["slam"]["position_rmse_m"] <= 0.2
    for robot in metrics["robots"].values():
        assert robot["slam"]["position_rmse_m"] < robot["dead_reckoning"]["position_rmse_m"]
    assert metrics["landmarks"]["rmse_m"] <= 0.3
    assert json.loads((tmp_path / "metrics.json").read_text())["known_association"] is True
    assert (tmp_path / "robot1_slam.tum").is_file() and (tmp_path / "trajectories.png").is_file()
