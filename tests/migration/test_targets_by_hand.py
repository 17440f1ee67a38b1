"""extract_targets on a volume drawn in the test: one pipe and one compact target, each where it was drawn, with
the scores, column counts and order the docstring gives; the depth cut, and the smallest part that counts."""

import numpy as np
import pytest

from gpr3d.core.grid import Grid3D
from gpr3d.migration.targets import extract_targets, ridge_map

GRID = Grid3D(0.0, 0.0, 0.0, 0.01, 0.01, 0.005, 80, 80, 40)


def _column(env, i, j, k, amp):
    """A symmetric peak in depth (its parabola's vertex is the cell itself)."""
    env[i, j, k] = amp
    env[i, j, k - 1] = env[i, j, k + 1] = 0.5 * amp


def _volume(disc_r=2.0):
    env = np.zeros(GRID.shape, np.float32)
    for i in range(10, 61):  # a pipe along x at y = 0.2 m, top 0.1 m deep, from 0.10 to 0.60 m
        _column(env, i, 20, 20, 1.0)
    cells = [(i, j) for i in range(44, 57) for j in range(49, 62) if (i - 50) ** 2 + (j - 55) ** 2 <= disc_r**2]
    for i, j in cells:  # a compact target around (0.50, 0.55), 0.06 m deep
        _column(env, i, j, 12, 0.8)
    return env, cells


def test_a_pipe_and_a_compact_target_where_they_were_drawn():
    env, cells = _volume()
    val, dep = ridge_map(env, GRID)
    peak = np.percentile(val, 99.5)
    assert peak == pytest.approx(1.0)
    out = extract_targets(env, GRID)
    assert [t.kind for t in out] == ["line", "point"]  # ordered by score x columns: 51 x 1.0, then 13 x 0.8
    line, pt = out
    # ends: the 2 % and 98 % quantiles of 51 equal columns, 0.10 .. 0.60 m: the 2nd and the 50th
    ends = sorted(line.points_xyz)
    np.testing.assert_allclose(ends, [[0.11, 0.2, 0.1], [0.59, 0.2, 0.1]], atol=1e-6)
    assert line.depth_m == pytest.approx(0.1, abs=1e-6)
    assert line.score == pytest.approx(1.0) and line.n_voxels == 51
    assert len(cells) == 13
    np.testing.assert_allclose(pt.points_xyz, [[0.5, 0.55, 0.06]], atol=1e-6)
    assert pt.depth_m == pytest.approx(0.06, abs=1e-6)
    assert pt.score == pytest.approx(0.8) and pt.n_voxels == 13


def test_the_depth_cut_on_a_cell_and_below_it():
    env, _ = _volume()
    kept = extract_targets(env, GRID, min_depth_m=0.06)  # on the target's own cell: kept, at its depth
    assert [(t.kind, round(t.depth_m, 6)) for t in kept] == [("line", 0.1), ("point", 0.06)]
    deeper = extract_targets(env, GRID, min_depth_m=0.08)
    assert [(t.kind, round(t.depth_m, 6)) for t in deeper] == [("line", 0.1)]


def test_the_smallest_compact_target_has_six_columns():
    env5, cells5 = _volume(disc_r=1.0)  # 5 cells: a plus sign
    assert len(cells5) == 5
    assert [t.kind for t in extract_targets(env5, GRID)] == ["line"]
    env6 = env5.copy()
    _column(env6, 51, 56, 12, 0.8)
    assert [(t.kind, t.n_voxels) for t in extract_targets(env6, GRID)] == [("line", 51), ("point", 6)]
