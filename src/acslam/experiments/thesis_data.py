"""The thesis's own timing and coverage numbers (§5.5), transcribed for side-by-side tables.

Real TurtleBot3 runs in the PIC4SeR lab, one trial per configuration. The thesis used
*robot_13* alone, then added *robot_12*, then *robot_14*; our worlds put the
single-robot start first (``acslam.worlds.thesis``), so robot_13 -> robot_0,
robot_12 -> robot_1, robot_14 -> robot_2. Keys are experiment -> robot count.
"""

from __future__ import annotations

THESIS_ROBOT = {"robot_13": "robot_0", "robot_12": "robot_1", "robot_14": "robot_2"}

# Tables 5.1, 5.5, 5.9, 5.13 (exploration time [s] per robot) and §5.5.5 (exp5, text).
TIMING_SOURCE = {1: "Table 5.1", 2: "Table 5.5", 3: "Table 5.9", 4: "Table 5.13", 5: "§5.5.5, text"}
TIMING_S: dict[int, dict[int, dict[str, float]]] = {
    1: {
        1: {"robot_13": 165.404},
        2: {"robot_12": 129.724, "robot_13": 133.751},
        3: {"robot_12": 158.238, "robot_13": 105.732, "robot_14": 135.568},
    },
    2: {
        1: {"robot_13": 141.704},
        2: {"robot_12": 94.105, "robot_13": 94.709},
        3: {"robot_12": 86.612, "robot_13": 58.303, "robot_14": 65.513},
    },
    3: {
        1: {"robot_13": 114.411},
        2: {"robot_12": 66.002, "robot_13": 68.999},
        3: {"robot_12": 86.699, "robot_13": 70.359, "robot_14": 66.339},
    },
    4: {
        1: {"robot_13": 220.707},
        2: {"robot_12": 102.321, "robot_13": 113.801},
        3: {"robot_12": 106.500, "robot_13": 99.906, "robot_14": 96.816},
    },
}
# The tables' "Gap time" rows, as printed (not recomputed: the thesis rounds per robot).
GAP_S: dict[int, dict[int, float]] = {
    1: {2: 4.027, 3: 52.505},
    2: {2: 0.603, 3: 28.308},
    3: {2: 2.997, 3: 20.360},
    4: {2: 11.480, 3: 9.684},
}
# Experiment 5 reports only the team's execution time.
TOTAL_S: dict[int, dict[int, float]] = {5: {3: 223.219}}

# Tables 5.3, 5.7, 5.11, 5.15, 5.17: (area [m^2], rate [%]) per combination of robots, as
# printed. A rate is the area over the team's to within 1 %, except Table 5.3(b) robot_12:
# 59.29 m^2 of 64.75 m^2 is 91.57 %, printed as 80.75 %.
COVERAGE_SOURCE = {
    1: "Table 5.3",
    2: "Table 5.7",
    3: "Table 5.11",
    4: "Table 5.15",
    5: "Table 5.17",
}
_ONE, _TWO = ("robot_13",), ("robot_12", "robot_13")
_THREE = (
    ("robot_12",),
    ("robot_13",),
    ("robot_14",),
    ("robot_12", "robot_13"),
    ("robot_12", "robot_14"),
    ("robot_13", "robot_14"),
    ("robot_12", "robot_13", "robot_14"),
)


def _rows(
    combos: tuple[tuple[str, ...], ...], values: list[tuple[float, float]]
) -> dict[tuple[str, ...], tuple[float, float]]:
    return dict(zip(combos, values, strict=True))


COVERAGE: dict[int, dict[int, dict[tuple[str, ...], tuple[float, float]]]] = {
    1: {
        1: _rows((_ONE,), [(64.79, 100.00)]),
        2: _rows((_TWO[:1], _TWO[1:], _TWO), [(59.29, 80.75), (52.00, 80.30), (64.75, 100.00)]),
        3: _rows(
            _THREE,
            [
                (58.74, 90.27),
                (41.38, 63.60),
                (43.76, 67.25),
                (62.79, 96.50),
                (62.26, 95.69),
                (57.63, 88.57),
                (65.07, 100.00),
            ],
        ),
    },
    2: {
        1: _rows((_ONE,), [(63.71, 100.00)]),
        2: _rows((_TWO[:1], _TWO[1:], _TWO), [(51.63, 80.72), (51.14, 79.95), (63.96, 100.00)]),
        3: _rows(
            _THREE,
            [
                (53.02, 82.50),
                (47.56, 74.01),
                (49.06, 76.33),
                (60.42, 94.01),
                (62.95, 97.95),
                (53.54, 83.31),
                (64.70, 100.00),
            ],
        ),
    },
    3: {
        1: _rows((_ONE,), [(64.46, 100.00)]),
        2: _rows((_TWO[:1], _TWO[1:], _TWO), [(53.37, 82.73), (50.19, 77.80), (64.90, 100.00)]),
        3: _rows(
            _THREE,
            [
                (50.67, 79.43),
                (46.79, 73.35),
                (49.42, 77.47),
                (57.02, 89.38),
                (63.11, 98.93),
                (55.82, 87.50),
                (64.28, 100.00),
            ],
        ),
    },
    4: {
        1: _rows((_ONE,), [(64.65, 100.00)]),
        2: _rows((_TWO[:1], _TWO[1:], _TWO), [(47.59, 73.21), (52.89, 81.37), (65.00, 100.00)]),
        3: _rows(
            _THREE,
            [
                (40.88, 65.29),
                (46.97, 75.02),
                (48.67, 77.74),
                (57.75, 92.24),
                (60.01, 95.84),
                (54.74, 87.42),
                (63.16, 100.00),
            ],
        ),
    },
    5: {
        3: _rows(
            _THREE,
            [
                (67.26, 67.52),
                (60.80, 61.04),
                (50.88, 51.06),
                (86.02, 86.35),
                (87.29, 87.63),
                (75.78, 76.08),
                (99.61, 100.00),
            ],
        ),
    },
}


# §5.2 and §5.4: what the thesis says of each environment (its figures are photos) and of
# the starts ("predefined starting locations", not given).
ENVIRONMENT = {
    1: "a closed start area with a single opening: one initial frontier, at most two more "
    "found later",
    2: "three initial frontiers, one per robot",
    3: "a slightly more complex structure with four initial frontiers",
    4: "a labyrinth-style structure with five initial frontiers",
    5: "a big area of the PIC4SeR floor: the laboratory and other rooms",
}
STARTS = "predefined starting locations, not given"


def thesis_team_area_m2(experiment: int) -> float | None:
    """The area the largest team mapped (the 100 % row of the coverage table) [m^2]."""
    teams = COVERAGE.get(experiment, {})
    if not teams:
        return None
    rows = teams[max(teams)]
    return max(area for area, _ in rows.values())


def our_combination(thesis_robots: tuple[str, ...]) -> str:
    """``("robot_12", "robot_13")`` -> ``"robot_0+robot_1"`` (our metrics.json key)."""
    ours = sorted(THESIS_ROBOT[name] for name in thesis_robots)
    return "+".join(ours)


def thesis_timing(experiment: int, robots: int) -> dict[str, float] | None:
    """Per-robot times (our names), ``total`` and (teams) ``gap`` [s]; None if not run."""
    per_robot = TIMING_S.get(experiment, {}).get(robots)
    if per_robot is None:
        total = TOTAL_S.get(experiment, {}).get(robots)
        return None if total is None else {"total": total}
    times = {THESIS_ROBOT[name]: t for name, t in per_robot.items()}
    gap = GAP_S[experiment].get(robots)
    return {**times, "total": max(times.values())} | ({} if gap is None else {"gap": gap})


def thesis_coverage(experiment: int, robots: int) -> dict[str, tuple[float, float]]:
    """(area [m^2], rate [0-1]) per our combination key; empty if not run."""
    rows = COVERAGE.get(experiment, {}).get(robots, {})
    return {our_combination(combo): (area, rate / 100) for combo, (area, rate) in rows.items()}
