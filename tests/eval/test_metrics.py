"""Metrics against hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from acslam.eval.metrics import (
    confusion_rates,
    coverage_by_combination,
    exploration_times,
    explored_areas,
    localization_errors,
    timing,
    waste,
)


def test_shifted_trajectory_has_the_shift_as_error() -> None:
    true_stamps = np.linspace(0.0, 10.0, 101)
    truth = np.column_stack([true_stamps, np.sin(true_stamps), np.full(101, 0.3)])
    stamps = np.array([0.05, 2.0, 5.55, 9.95])  # between truth samples: interpolated
    expected = np.column_stack(
        [stamps, np.interp(stamps, true_stamps, truth[:, 1]), np.full(4, 0.3)]
    )
    estimate = expected + np.array([0.3, -0.4, 0.1])  # 0.5 m off, 0.1 rad off everywhere
    errors = localization_errors(stamps, estimate, true_stamps, truth)
    for key in ("final_dist_m", "mae_m", "rmse_m"):
        assert errors[key] == pytest.approx(0.5)
    assert errors["std_m"] == pytest.approx(0.0, abs=1e-12)
    assert errors["rmse_yaw_rad"] == pytest.approx(0.1)


def test_errors_of_growing_drift() -> None:
    true_stamps = np.array([0.0, 1.0, 2.0, 3.0])
    truth = np.zeros((4, 3))
    estimate = np.column_stack([[0.0, 1.0, 2.0, 3.0], np.zeros(4), [0.0, 0.0, math.pi, -3.0]])
    errors = localization_errors(true_stamps, estimate, true_stamps, truth)
    assert errors["mae_m"] == pytest.approx(1.5)
    assert errors["rmse_m"] == pytest.approx(math.sqrt(14 / 4))
    assert errors["std_m"] == pytest.approx(np.std([0, 1, 2, 3]))
    assert errors["final_dist_m"] == pytest.approx(3.0)
    assert errors["final_yaw_rad"] == pytest.approx(3.0)  # wrapped, not 2 pi - 3
    assert errors["mae_yaw_rad"] == pytest.approx((math.pi + 3.0) / 4)


def test_yaw_error_wraps_across_pi() -> None:
    stamps = np.array([0.0, 1.0])
    truth = np.array([[0.0, 0.0, math.pi - 0.05], [0.0, 0.0, -math.pi + 0.05]])
    estimate = np.array([[0.0, 0.0, -math.pi + 0.05], [0.0, 0.0, math.pi - 0.05]])
    errors = localization_errors(stamps, estimate, stamps, truth)
    assert errors["mae_yaw_rad"] == pytest.approx(0.1)


def test_confusion_counts_of_a_tiny_grid() -> None:
    truth = np.array([[True, True, False], [False, False, True]])
    estimate = np.array([[100, 0, 0], [100, -1, -1]])
    # TP (0,0); FN (0,1); TN (0,2); FP (1,0); (1,1) and (1,2) unknown, not scored.
    rates = confusion_rates(truth, estimate)
    assert (rates["tp"], rates["fn"], rates["tn"], rates["fp"]) == (1, 1, 1, 1)
    assert rates["accuracy"] == pytest.approx(0.5)
    assert rates["tpr"] == pytest.approx(0.5) and rates["fnr"] == pytest.approx(0.5)
    assert rates["tnr"] == pytest.approx(0.5) and rates["fpr"] == pytest.approx(0.5)


def test_coverage_of_combinations() -> None:
    a = np.array([1, 1, 1, 0, 0, 0], dtype=bool)
    b = np.array([0, 0, 1, 1, 0, 0], dtype=bool)
    c = np.array([0, 0, 0, 0, 0, 1], dtype=bool)
    cov = coverage_by_combination({"robot_0": a, "robot_1": b, "robot_2": c}, 0.25)
    assert list(cov) == [
        "robot_0",
        "robot_1",
        "robot_2",
        "robot_0+robot_1",
        "robot_0+robot_2",
        "robot_1+robot_2",
        "robot_0+robot_1+robot_2",
    ]
    assert cov["robot_0"] == {"area_m2": 0.75, "rate": 0.6}
    assert cov["robot_0+robot_1"] == {"area_m2": 1.0, "rate": 0.8}
    assert cov["robot_1+robot_2"]["area_m2"] == 0.75
    assert cov["robot_0+robot_1+robot_2"] == {"area_m2": 1.25, "rate": 1.0}


def test_waste_is_overlap_over_the_union_and_path_lengths() -> None:
    a = np.array([1, 1, 1, 0, 0, 0], dtype=bool)
    b = np.array([0, 0, 1, 1, 0, 0], dtype=bool)
    c = np.array([0, 0, 1, 0, 0, 1], dtype=bool)
    paths = {
        "robot_0": np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]]),  # 3 + 4 m
        "robot_1": np.array([[1.0, 1.0], [4.0, 5.0]]),  # a 3-4-5 triangle's hypotenuse
        "robot_2": np.array([[2.0, 2.0]]),  # never moved
    }
    spent = waste({"robot_0": a, "robot_1": b, "robot_2": c}, paths, 0.25, "ground truth")
    # Cell 2 is in three masks; 5 cells are in any: 1 of 5 overlaps.
    assert spent["overlap_area_m2"] == 0.25
    assert spent["overlap_ratio"] == pytest.approx(0.2)
    assert spent["travelled_m"] == {"robot_0": 7.0, "robot_1": 5.0, "robot_2": 0.0}
    assert spent["travelled_total_m"] == 12.0
    alone = waste({"robot_0": a}, {"robot_0": paths["robot_0"]}, 0.25, "estimate")
    assert (alone["overlap_ratio"], alone["travelled_from"]) == (0.0, "estimate")


def test_timing_gap() -> None:
    result = timing({"robot_0": 129.7, "robot_1": 133.75})
    assert result["total_s"] == 133.75
    assert result["gap_s"] == pytest.approx(4.05)


def test_timing_of_a_robot_still_exploring_is_unknown() -> None:
    result = timing({"robot_0": 40.0, "robot_1": None})
    assert result["per_robot_s"] == {"robot_0": 40.0, "robot_1": None}
    assert result["total_s"] is None and result["gap_s"] is None


@pytest.mark.parametrize(
    ("explored", "expected"),
    [
        # The team finished: idle robots at the moment they became idle, a robot that never
        # did at the end, a lost robot when it was lost.
        (True, [31.0, 50.0, 12.5]),
        # Stopped (time limit, error): only the lost robot has a time; the others were
        # still exploring, whether or not they were idle at that moment.
        (False, [None, None, 12.5]),
    ],
)
def test_exploration_times(explored: bool, expected: list[float | None]) -> None:
    times = exploration_times(explored, (31.0, None, 20.0), {2: 12.5}, end_s=50.0)
    assert times == expected


def test_explored_areas_of_a_tiny_grid() -> None:
    # 3 x 4 cells of 0.25 m^2; the map knows 7 cells, the true reachable free area is 5
    # cells, of which the map knows 3 (the other 4 known cells are walls or out of reach).
    known = np.array([[1, 1, 1, 1], [1, 1, 0, 0], [0, 1, 0, 0]], dtype=bool)
    reachable = np.array([[0, 1, 1, 0], [0, 0, 1, 1], [0, 1, 0, 0]], dtype=bool)
    areas = explored_areas(known, reachable, 0.25)
    assert areas == {
        "mapped_area_m2": 1.75,
        "reachable_area_m2": 1.25,
        "mapped_reachable_area_m2": 0.75,
        "explored_fraction_of_reachable": 0.6,
    }
    assert math.isnan(
        explored_areas(known, np.zeros_like(known), 0.25)["explored_fraction_of_reachable"]
    )
