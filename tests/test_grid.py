"""Grid geometry and Bresenham lines against brute-force references."""

from __future__ import annotations

import numpy as np

from acslam.grid import GridSpec, bresenham, window_around


def test_world_cell_round_trip() -> None:
    spec = GridSpec(-2.0, 1.0, 0.05, 40, 60)
    cells = np.array([[0, 0], [39, 59], [10, 3]])
    centres = spec.cell_to_world(cells)
    assert np.allclose(centres[0], [-1.975, 1.025])
    assert (spec.world_to_cell(centres) == cells).all()
    assert spec.contains(np.array([[40, 0], [-1, 0], [39, 59]])).tolist() == [False, False, True]


def test_bresenham_matches_reference_lines() -> None:
    rng = np.random.default_rng(7)
    for _ in range(500):
        r0, c0, r1, c1 = (int(v) for v in rng.integers(-30, 30, size=4))
        line = bresenham(r0, c0, r1, c1)
        n = max(abs(r1 - r0), abs(c1 - c0)) + 1
        assert line.shape == (n, 2)
        assert line[0].tolist() == [r0, c0] and line[-1].tolist() == [r1, c1]
        steps = np.abs(np.diff(line, axis=0))
        assert (steps.max(axis=1) == 1).all()  # 8-connected, one major-axis step each
        # Every cell lies within half a cell (in the minor axis) of the ideal segment.
        if n > 1:
            t = np.linspace(0.0, 1.0, n)
            ideal = np.column_stack([r0 + t * (r1 - r0), c0 + t * (c1 - c0)])
            minor = 1 if abs(r1 - r0) >= abs(c1 - c0) else 0
            assert np.abs(line[:, minor] - ideal[:, minor]).max() <= 0.5 + 1e-9


def test_a_window_around_a_point_holds_exactly_the_cells_near_it_within_the_grid() -> None:
    spec = GridSpec(-1.0, 2.0, 0.1, 50, 80)
    rng = np.random.default_rng(3)
    for _ in range(100):
        center = rng.uniform([-3.0, 0.0], [9.0, 9.0])
        half = float(rng.uniform(0.05, 2.0))
        window = window_around(spec, center, half)
        cells = np.argwhere(np.ones(spec.shape, dtype=bool))
        xy = spec.cell_to_world(cells)
        # Brute force: the cells whose squares reach within half of the point, per axis.
        near = np.all(np.abs(xy - center) < half + spec.resolution_m / 2, axis=1)
        if near.any():
            inside = cells[near]
            assert (window.row0, window.col0) == tuple(inside.min(axis=0))
            assert window.spec.shape == tuple(inside.max(axis=0) - inside.min(axis=0) + 1)
        else:
            assert window.spec.shape[0] >= 1 and window.spec.shape[1] >= 1
        np.testing.assert_allclose(
            window.spec.cell_to_world(np.zeros((1, 2), dtype=int)),
            spec.cell_to_world(np.array([[window.row0, window.col0]])),
        )
