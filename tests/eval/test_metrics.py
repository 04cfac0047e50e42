"""Metrics against hand-computed cases."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import minimize

from acslam.eval.frames import world_values
from acslam.eval.metrics import (
    confusion_rates,
    coverage_by_combination,
    exploration_times,
    explored_areas,
    localization_errors,
    team_alignment,
    timing,
    waste,
)
from acslam.grid import OCCUPIED, UNKNOWN, GridSpec


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


def _team_truth() -> list[tuple[np.ndarray, np.ndarray]]:
    """Two robots' true trajectories (stamps, poses), 21 samples each, on different paths."""
    stamps = np.linspace(0.0, 20.0, 21)
    first = np.column_stack([stamps, 0.5 * np.sin(stamps / 3), np.zeros(21)])
    second = np.column_stack([10.0 - 0.4 * stamps, 3.0 + 0.2 * stamps, np.full(21, 2.0)])
    return [(stamps, first), (stamps, second)]


def _turned(
    poses: np.ndarray, angle_rad: float, centre: np.ndarray, shift: np.ndarray
) -> np.ndarray:
    """``poses`` turned by ``angle_rad`` about ``centre``, then moved by ``shift``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    xy = (poses[:, :2] - centre) @ np.array([[c, s], [-s, c]]) + centre + shift
    return np.column_stack([xy, poses[:, 2] + angle_rad])


def test_team_alignment_undoes_a_rigid_motion_of_the_whole_team() -> None:
    """The estimate is the truth turned 0.012 rad about (3, 4) and shifted: after the
    alignment nothing is left, and the transform is that motion's inverse."""
    angle, centre, shift = 0.012, np.array([3.0, 4.0]), np.array([0.05, -0.02])
    team = [
        (stamps, _turned(truth, angle, centre, shift), stamps, truth)
        for stamps, truth in _team_truth()
    ]
    alignment = team_alignment(team)
    assert alignment["aligned_rmse_m"] == pytest.approx(0.0, abs=1e-12)
    assert alignment["rotation_rad"] == pytest.approx(-angle, abs=1e-12)
    # The inverse of q = R(p - c) + c + d is p = R^-1 q + c - R^-1 (c + d).
    c, s = math.cos(angle), math.sin(angle)
    inverse_rotation = np.array([[c, s], [-s, c]])
    assert alignment["translation_m"] == pytest.approx(
        list(centre - inverse_rotation @ (centre + shift)), abs=1e-12
    )
    # Everything moved by the shift, and by the turn about (3, 4) in proportion to its
    # distance from there: the mean position of the samples moves by the same.
    samples = np.vstack([truth[:, :2] for _, truth in _team_truth()])
    moved = _turned(np.column_stack([samples, np.zeros(len(samples))]), angle, centre, shift)
    expected_shift_m = np.hypot(*(moved[:, :2].mean(axis=0) - samples.mean(axis=0)))
    assert alignment["centroid_shift_m"] == pytest.approx(expected_shift_m, abs=1e-12)
    assert localization_errors(*team[1])["rmse_m"] > 0.05  # the plain RMSE sees the turn


def test_team_alignment_is_one_transform_for_all_robots() -> None:
    """One robot 0.1 m east of its truth, the other 0.1 m west, on the same path: no one
    motion of the team fixes both, so the aligned RMSE stays 0.1 m."""
    stamps, truth = _team_truth()[0]
    offset = np.array([0.1, 0.0, 0.0])
    east, west = truth + offset, truth - offset
    alignment = team_alignment([(stamps, east, stamps, truth), (stamps, west, stamps, truth)])
    assert alignment["aligned_rmse_m"] == pytest.approx(0.1)
    assert alignment["rotation_rad"] == pytest.approx(0.0, abs=1e-12)


def test_team_alignment_matches_a_numerical_minimum() -> None:
    """Noisy estimates: the closed form's RMSE and rotation equal a numerical minimisation
    of the pooled squared error over (rotation, x, y)."""
    rng = np.random.default_rng(5)
    team = [
        (stamps, _turned(truth, -0.03, np.array([1.0, 2.0]), np.array([0.2, 0.1]))
         + rng.normal(0.0, 0.05, truth.shape), stamps, truth)
        for stamps, truth in _team_truth()
    ]  # fmt: skip
    estimate = np.vstack([e[:, :2] for _, e, _, _ in team])
    truth = np.vstack([t[:, :2] for _, _, _, t in team])

    def mean_squared_m2(x: np.ndarray) -> float:
        c, s = math.cos(x[0]), math.sin(x[0])
        moved = estimate @ np.array([[c, s], [-s, c]]) + x[1:]
        return float(np.mean(np.sum((moved - truth) ** 2, axis=1)))

    best = minimize(mean_squared_m2, np.zeros(3), method="Nelder-Mead",
                    options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 20000})  # fmt: skip
    alignment = team_alignment(team)
    assert alignment["aligned_rmse_m"] == pytest.approx(math.sqrt(best.fun), rel=1e-6)
    assert alignment["rotation_rad"] == pytest.approx(best.x[0], abs=1e-6)
    assert alignment["translation_m"] == pytest.approx(list(best.x[1:]), abs=1e-6)


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


def _wall_map(wall_row: int) -> tuple[GridSpec, np.ndarray, np.ndarray]:
    """A 10 m x 10 m grid at 5 cm with one straight wall along row 100 (y = 5 m), and a
    map that knows rows 80-120 with its wall on ``wall_row`` instead."""
    spec = GridSpec(0.0, 0.0, 0.05, 200, 200)
    true_occupied = np.zeros(spec.shape, dtype=bool)
    true_occupied[100, 20:181] = True
    values = np.full(spec.shape, UNKNOWN, dtype=np.int8)
    values[80:121, 10:191] = 0
    values[wall_row, 20:181] = OCCUPIED
    return spec, true_occupied, values


@pytest.mark.parametrize("framed", [False, True])
def test_a_map_moved_by_the_teams_alignment_scores_what_it_is_inside(framed: bool) -> None:
    """A map right inside but 0.5 m off as a whole: 161 wall cells missed and 161 walls
    where there are none, of the 41 x 181 mapped; moved back by the alignment, every cell
    is right. With unknown starts the motion joins each frame's placement."""
    spec, true_occupied, values = _wall_map(wall_row=110)
    view = SimpleNamespace(
        robot_ids=(0,), spec=spec, snapshot=SimpleNamespace(map=SimpleNamespace(
            occupancy_values=lambda: values))
    )  # fmt: skip
    snapshot = SimpleNamespace(frames=(view,) if framed else (), map=view.snapshot.map)
    starts = np.zeros((1, 3))
    as_is = confusion_rates(true_occupied, world_values(snapshot, starts, spec))
    assert as_is["accuracy"] == pytest.approx((41 * 181 - 2 * 161) / (41 * 181))
    moved = world_values(snapshot, starts, spec, np.array([0.0, -0.5, 0.0]))
    assert confusion_rates(true_occupied, moved)["accuracy"] == 1.0
