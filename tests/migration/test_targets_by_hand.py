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


# --- the pieces, each on inputs worked out by hand ------------------------------------------------------------------

from gpr3d.migration.targets import Target3D, _chain_runs, _depth_fit, _extent, join_collinear  # noqa: E402


def _line(a, b, score=1.0, n=10, **extra):
    return Target3D("line", [list(a), list(b)], min(a[2], b[2]), score, n, dict(extra))


def test_join_collinear_joins_pieces_across_a_gap_and_weighs_their_scores():
    a = _line((0.0, 0.0, 0.10), (1.0, 0.0, 0.12), score=2.0, n=30)
    b = _line((1.5, 0.01, 0.13), (2.0, 0.0, 0.14), score=1.0, n=10)  # 0.5 m on, 1 cm aside, on a's depth line
    (j,) = join_collinear([a, b], tol_m=0.02, join_gap_m=0.6)
    np.testing.assert_allclose(j.points_xyz, [[0.0, 0.0, 0.10], [2.0, 0.0, 0.14]])
    assert j.depth_m == pytest.approx(0.10) and j.n_voxels == 40
    assert j.score == pytest.approx((2.0 * 30 + 1.0 * 10) / 40) and j.extra == {"joined": 2}
    # b given first, reversed: the same line, from a's first end (the least along b's axis) to the farthest
    (j2,) = join_collinear([_line((2.0, 0.0, 0.14), (1.5, 0.0, 0.13), 1.0, 10), a], tol_m=0.02, join_gap_m=0.6)
    np.testing.assert_allclose(sorted(j2.points_xyz), [[0.0, 0.0, 0.10], [2.0, 0.0, 0.14]])
    # three pieces: the counts of joined pieces add up
    c = _line((2.3, 0.0, 0.145), (2.8, 0.0, 0.155), score=1.0, n=10, joined=2)
    (j3,) = join_collinear([a, b, c], tol_m=0.02, join_gap_m=0.6)
    assert j3.extra == {"joined": 4} and j3.n_voxels == 50
    # a piece behind a's start joins too (the gap measured back from it)
    back = _line((-0.9, 0.0, 0.082), (-0.4, 0.0, 0.092), n=5)
    (jb,) = join_collinear([a, back], tol_m=0.02, join_gap_m=0.6)
    np.testing.assert_allclose(sorted(jb.points_xyz)[0], [-0.9, 0.0, 0.082])


@pytest.mark.parametrize("change, joined", [
    ({"gap": 0.59}, True), ({"gap": 0.61}, False),  # the gap, against join_gap_m 0.6
    ({"aside": 0.019}, True), ({"aside": 0.021}, False),  # horizontal offset from a's axis, tol 0.02
    ({"deeper": 0.019}, True), ({"deeper": 0.021}, False),  # off a's depth line
    ({"turn_deg": 2.9}, True), ({"turn_deg": 3.1}, False),  # the angle between them, 3 deg at most
])
def test_join_collinear_limits(change, joined):
    a = _line((0.0, 0.0, 0.1), (1.0, 0.0, 0.1))
    g, dy, dz = change.get("gap", 0.3), change.get("aside", 0.0), change.get("deeper", 0.0)
    t = change.get("turn_deg", 0.0)
    d = np.array([np.cos(np.radians(t)), np.sin(np.radians(t))])
    p0 = np.array([1.0 + g, dy])
    p1 = p0 + 0.05 * d  # short, so that a turn moves its far end little
    b = _line((*p0, 0.1 + dz), (*p1, 0.1 + dz))
    out = join_collinear([a, b], tol_m=0.02, join_gap_m=0.6)
    assert (len(out) == 1) == joined


def test_chain_runs_take_in_the_short_pieces_beyond_a_line_on_both_sides():
    """Runs split at gaps over run_gap; the long run (a line) takes in the short ones beyond each end that are
    close enough, strong enough and at its depth, one after the other, and stops at the first that is not."""
    cell = 0.01
    pieces = [(-0.20, 4, 1.0, 0.10),  # far left: reached through the next one (0.09 m before it)
              (-0.08, 4, 1.0, 0.10),  # left, 0.05 m before the line
              (0.0, 40, 1.0, 0.10),  # the line: 0.40 m
              (0.47, 4, 1.0, 0.10),  # right, 0.08 m after it
              (0.58, 4, 0.2, 0.10),  # weak: stops the chain on the right
              (0.69, 4, 1.0, 0.10)]  # beyond the weak one: not reached
    s = np.concatenate([a + cell * np.arange(n) for a, n, _, _ in pieces])
    w = np.concatenate([np.full(n, v) for _, n, v, _ in pieces])
    z = np.concatenate([np.full(n, d) for _, n, _, d in pieces])
    kw = dict(run_gap=0.04, join_gap=0.1, min_columns=3, min_line=0.3, min_density=0.5, cell=cell, level=0.5,
              depth_tol=0.02)
    (line,) = _chain_runs(s, w, z, **kw)
    np.testing.assert_array_equal(line, np.arange(4 + 4 + 40 + 4))
    # the same on the far side when the weak piece is strong; a piece off the line's depth stops it instead
    w2 = w.copy()
    w2[52:56] = 1.0
    (line2,) = _chain_runs(s, w2, z, **kw)
    np.testing.assert_array_equal(line2, np.arange(len(s)))
    z2 = z.copy()
    z2[52:56] = 0.13
    (line3,) = _chain_runs(s, w2, z2, **kw)
    np.testing.assert_array_equal(line3, np.arange(52))
    # a gap past join_gap stops it; pieces under min_columns are dropped before anything
    (line4,) = _chain_runs(s, w, z, **{**kw, "join_gap": 0.07})
    np.testing.assert_array_equal(line4, np.arange(4, 48))
    assert _chain_runs(s, w, z, **{**kw, "min_line": 0.5}) == []


def test_extent_depth_fit_by_hand():
    s = np.array([0.0, 0.1, 0.2, 0.3, 0.4])
    # weighted quantiles: cumulative weights 0.1 0.2 0.3 0.9 1.0 -> 0.25 falls on the 3rd, 0.75 on the 4th
    assert _extent(s, np.array([1.0, 1.0, 1.0, 6.0, 1.0]), 0.25) == (0.2, 0.3)
    assert _extent(s[::-1], np.array([1.0, 6.0, 1.0, 1.0, 1.0]), 0.25) == (0.2, 0.3)  # any order
    # q = 0: the plain 1st and 99th percentiles
    lo, hi = _extent(s, np.ones(5), 0.0)
    assert (lo, hi) == (pytest.approx(0.004), pytest.approx(0.396))
    # depth fit: a dipping line with one column far off (a crossing target) left out of the weighted fit
    x = np.linspace(0.0, 1.0, 11)
    d = 0.1 + 0.05 * x
    d[4] = 0.02
    np.testing.assert_allclose(_depth_fit(x, d, np.ones(11), 0.005), [0.05, 0.1], atol=1e-9)
    # two columns, or all at one place: the weighted mean depth, flat
    np.testing.assert_allclose(_depth_fit(x[:2], np.array([0.1, 0.2]), np.array([3.0, 1.0]), 0.005), [0.0, 0.125])
    np.testing.assert_allclose(_depth_fit(np.full(4, 0.3), np.array([0.1, 0.2, 0.1, 0.2]), np.ones(4), 0.005),
                               [0.0, 0.15])
    # three columns make a fit
    np.testing.assert_allclose(_depth_fit(x[:3], 0.1 + 0.05 * x[:3], np.ones(3), 0.005), [0.05, 0.1], atol=1e-9)


def test_ridge_map_refines_depth_by_the_parabola_and_keeps_the_ends():
    g = Grid3D(0.0, 0.0, 0.2, 0.01, 0.01, 0.01, 1, 4, 6)
    env = np.zeros(g.shape, np.float32)
    env[0, 0, 2:5] = [0.5, 1.0, 0.75]  # vertex at 3 + 0.5 (0.5 - 0.75) / (0.5 - 2 + 0.75) = 3 + 1/6
    env[0, 1, 0:2] = [1.0, 0.5]  # the top cell: no parabola
    env[0, 2, 4:6] = [0.5, 1.0]  # the bottom cell: none either
    env[0, 3, 1:4] = [0.9, 1.0, 0.2]  # a lopsided peak: 2 + 0.5 (0.9 - 0.2) / (0.9 - 2 + 0.2) = 2 - 7/18
    val, dep = ridge_map(env, g)
    np.testing.assert_allclose(val[0], [1.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(dep[0], [0.2 + 0.01 * (3 + 1 / 6), 0.2, 0.25, 0.2 + 0.01 * (2 - 7 / 18)], atol=1e-8)


def test_the_ringing_tail_below_the_cut_is_cleared_column_by_column():
    from gpr3d.migration.targets import _cut_tails

    env = np.array([[[3.0, 2.0, 1.5, 1.0, 2.0, 0.5]], [[1.0, 2.0, 3.0, 1.0, 0.5, 0.25]]], np.float32)
    # cut at 1: the first column still falls from the cell above for three cells (zeroed), then rises again; the
    # second rises at once (kept whole)
    np.testing.assert_array_equal(_cut_tails(env, 1), [[[0, 0, 0, 2.0, 0.5]], [[2.0, 3.0, 1.0, 0.5, 0.25]]])
    np.testing.assert_array_equal(_cut_tails(env, 2), [[[0, 0, 2.0, 0.5]], [[3.0, 1.0, 0.5, 0.25]]])
    flat = np.array([[[3.0, 3.0, 1.0, 2.0]]], np.float32)  # level with the cell above: not falling, kept
    np.testing.assert_array_equal(_cut_tails(flat, 1), [[[3.0, 1.0, 2.0]]])
    np.testing.assert_array_equal(_cut_tails(env, 5), [[[0.0]], [[0.0]]])  # one cell left, falling


def test_segment_distances_and_line_checks_by_hand():
    from gpr3d.migration.targets import _is_line, _seg_dists

    a, b = np.array([1.0, 1.0]), np.array([3.0, 1.0])
    q = np.array([[0.0, 1.0], [2.0, 1.5], [4.0, 2.0], [3.0, 1.0]])  # before a, beside, beyond b, on b
    np.testing.assert_allclose(_seg_dists(q, a, b), [1.0, 0.5, np.sqrt(2.0), 0.0])
    s = np.array([0.1, 0.2, 0.3, 0.5])
    L = s[-1] - s[0]
    assert _is_line(s, 4, L, 4 * 0.1 / L, 0.1)  # exactly long enough and dense enough
    assert not _is_line(s, 4, L + 1e-9, 0.5, 0.1)
    assert not _is_line(s, 4, L, 4 * 0.1 / L + 1e-9, 0.1)
    assert not _is_line(s, 2, L, 1.0, 0.1)  # two columns over 0.4 m: half a column per cell


def test_side_level_takes_the_brighter_side_s_dimmer_parallel():
    """val is banded by signed distance from the line a-b (a diagonal, on a grid that does not start at 0): on the
    left at 0.1 m 1.0 and at 0.2 m 0.5, on the right 0.8 and 0.9; the level is max(min(1.0, 0.5), min(0.8, 0.9))."""
    from gpr3d.migration.targets import _side_level

    g = Grid3D(1.0, 2.0, 0.0, 0.01, 0.01, 0.01, 100, 100, 1)
    a, b = np.array([1.3, 2.3]), np.array([1.6, 2.7])  # direction (0.6, 0.8), left normal (-0.8, 0.6)
    X, Y = np.meshgrid(g.x, g.y, indexing="ij")
    sd = (X - a[0]) * -0.8 + (Y - a[1]) * 0.6
    val = np.select([(sd > 0.05) & (sd < 0.15), (sd > 0.15) & (sd < 0.25), (sd < -0.05) & (sd > -0.15),
                     (sd < -0.15) & (sd > -0.25)], [1.0, 0.5, 0.8, 0.9], 0.0)
    assert _side_level(val, g, a, b, 0.1) == pytest.approx(0.8)
    assert _side_level(val, g, b, a, 0.1) == pytest.approx(0.8)  # either way round
    assert _side_level(val, g, a, b, 5.0) == 0.0  # every parallel outside the map


def test_fringe_is_a_near_parallel_segment_mostly_within_the_band():
    from gpr3d.migration.targets import _fringe

    found = [_line((1.0, 1.0, 0.1), (3.0, 1.0, 0.1))]

    def seg(x0, y0, length, deg):
        d = np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])
        p = np.array([x0, y0])
        return p, p + length * d

    assert _fringe(*seg(1.5, 1.05, 1.0, 0.0), found, 0.1)  # 5 cm beside it
    assert not _fringe(*seg(1.5, 1.15, 1.0, 0.0), found, 0.1)  # 15 cm: outside the band
    assert _fringe(*seg(1.5, 1.02, 0.5, 9.0), found, 0.2)  # 9 deg: near-parallel
    assert not _fringe(*seg(1.5, 1.02, 0.5, 11.0), found, 0.2)  # 11 deg: not
    assert not _fringe(*seg(1.0, 1.0, 2.0, 20.0), found, 1.0)  # long, inside a wide band, but 20 deg off
    # 0.705 of it within reach of the found segment's end (x <= 3.05 with band 0.05): 8 of the 11 samples
    assert _fringe(*seg(3.05 - 0.705, 1.0, 1.0, 0.0), found, 0.05 + 1e-9)
    assert not _fringe(*seg(3.05 - 0.6, 1.0, 1.0, 0.0), found, 0.05 + 1e-9)  # 7 of 11


def _trim_case(cross_deg=90.0, xb=0.62, both_ends=False):
    """Line A along x (0.00-0.50 m, 51 columns, then after a gap an end piece 0.60-0.64 m) and line B crossing the
    end piece at x = xb at ``cross_deg``; with ``both_ends`` line C crosses a start piece (-0.14 .. -0.10 m)."""
    xs = [np.round(np.arange(51) * 0.01, 6), 0.60 + 0.01 * np.arange(5)]
    if both_ends:
        xs.insert(0, -0.14 + 0.01 * np.arange(5))
    xa = np.concatenate(xs)
    P = [np.c_[xa, np.zeros_like(xa)]]
    W = [np.ones(len(xa))]
    t = np.radians(cross_deg)
    dB = np.array([np.cos(t), np.sin(t)])
    centre_b = np.array([xb, 0.0])
    yb = np.linspace(-0.3, 0.3, 61)
    P.append(centre_b + yb[:, None] * dB)
    W.append(np.ones(61))
    lines = [_line((xa[0], 0.0, 0.1), (xa[-1], 0.0, 0.1), n=len(xa)),
             _line((*(centre_b - 0.3 * dB), 0.2), (*(centre_b + 0.3 * dB), 0.2), n=61)]
    info = [(np.arange(len(xa)), np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 0.1])),
            (len(xa) + np.arange(61), centre_b, dB, np.array([0.0, 0.2]))]
    if both_ends:
        yc = np.linspace(-0.3, 0.3, 61)
        P.append(np.c_[np.full(61, -0.12), yc])
        W.append(np.ones(61))
        lines.append(_line((-0.12, -0.3, 0.3), (-0.12, 0.3, 0.3), n=61))
        info.append((len(xa) + 61 + np.arange(61), np.array([-0.12, 0.0]), np.array([0.0, 1.0]), np.array([0.0, 0.3])))
    return lines, info, np.vstack(P), np.concatenate(W)


def test_an_end_piece_on_a_crossing_line_is_cut_off():
    from gpr3d.migration.targets import _trim_crossings

    lines, info, P, W = _trim_case()
    _trim_crossings(lines, info, P, W, 0.05, 0.02, 0.5)
    a, b = lines
    # what is left: 0.00-0.50 m, ends at the 2 % and 98 % weighted quantiles of its 51 columns
    np.testing.assert_allclose(a.points_xyz, [[0.01, 0.0, 0.1], [0.49, 0.0, 0.1]], atol=1e-9)
    assert a.depth_m == pytest.approx(0.1) and a.extra == {"trimmed": True}
    assert b.extra == {} and b.points_xyz[0][1] == pytest.approx(-0.3)  # the crossing line is one piece: kept
    # both ends: the start piece on line C goes too
    lines, info, P, W = _trim_case(both_ends=True)
    _trim_crossings(lines, info, P, W, 0.05, 0.02, 0.5)
    np.testing.assert_allclose(lines[0].points_xyz, [[0.01, 0.0, 0.1], [0.49, 0.0, 0.1]], atol=1e-9)


@pytest.mark.parametrize("kw, trimmed", [
    ({"cross_deg": 70.0}, True), ({"cross_deg": 15.0}, False),  # crossing at 20 deg or more
    ({"xb": 0.665}, True), ({"xb": 0.675}, False),  # 3 or 2 of the piece's 5 columns within the band: half or more
])
def test_trimming_needs_a_real_crossing_over_half_the_piece(kw, trimmed):
    from gpr3d.migration.targets import _trim_crossings

    lines, info, P, W = _trim_case(**kw)
    before = [list(p) for p in lines[0].points_xyz]
    _trim_crossings(lines, info, P, W, 0.05, 0.02, 0.5)
    assert ("trimmed" in lines[0].extra) == trimmed
    if not trimmed:
        assert lines[0].points_xyz == before


BIG = Grid3D(0.0, 0.0, 0.0, 0.01, 0.01, 0.005, 150, 60, 160)


def _pipe(env, x0, x1, y, depth, amp=1.0, grid=BIG):
    """A pipe along x from x0 to x1 at y; ``depth(x)`` of its top, drawn as a symmetric peak on the nearest cell."""
    j = int(round((y - grid.y0) / grid.dy))
    for i in range(int(round(x0 / grid.dx)), int(round(x1 / grid.dx)) + 1):
        k = int(round((depth(i * grid.dx) - grid.d0) / grid.dd))
        _column(env, i, j, k, amp)


@pytest.mark.parametrize("gap, n_lines", [(0.45, 1), (0.55, 2)])
def test_collinear_pieces_join_across_gaps_under_half_a_metre(gap, n_lines):
    env = np.zeros(BIG.shape, np.float32)
    _pipe(env, 0.05, 0.5, 0.45, lambda x: 0.2)
    _pipe(env, 0.5 + gap, 0.5 + gap + 0.4, 0.45, lambda x: 0.2)
    lines = [t for t in extract_targets(env, BIG) if t.kind == "line"]
    assert len(lines) == n_lines
    if n_lines == 1:
        assert lines[0].extra.get("joined") == 2


@pytest.mark.parametrize("dip_deg, is_line", [(44.0, True), (45.5, False)])
def test_lines_dip_less_than_45_degrees(dip_deg, is_line):
    env = np.zeros(BIG.shape, np.float32)
    slope = np.tan(np.radians(dip_deg))
    _pipe(env, 0.2, 0.8, 0.45, lambda x: 0.1 + slope * (x - 0.2))
    lines = [t for t in extract_targets(env, BIG) if t.kind == "line"]
    assert bool(lines) == is_line
    if is_line:
        (ln,) = lines
        (x0, _, z0), (x1, _, z1) = sorted(ln.points_xyz)
        assert (z1 - z0) / (x1 - x0) == pytest.approx(slope, rel=0.02)


@pytest.mark.parametrize("layer, kept", [(0.6, True), (0.7, False)])
def test_a_pipe_must_stand_out_from_its_sides(layer, kept):
    """A bright layer on one side (both parallels 2.5 and 5 bands away lie on it): the pipe (1.0) stays while
    1.5 x the layer's level is under its own, and goes when it is over."""
    env = np.zeros(BIG.shape, np.float32)
    for j in range(0, 40):  # y 0 .. 0.39 m: the layer, 0.35 m deep (the pipe's parallels at y 0.25 and 0.0 m)
        for i in range(10, 141):
            _column(env, i, j, 70, layer)
    _pipe(env, 0.2, 1.2, 0.5, lambda x: 0.2)
    pipes = [t for t in extract_targets(env, BIG) if t.kind == "line" and abs(t.depth_m - 0.2) < 0.01]
    assert bool(pipes) == kept


def test_the_hough_accumulator_finds_weighs_and_forgets_lines():
    from gpr3d.migration.targets import _Hough, _line_dist

    rng = np.random.default_rng(7)
    for trial in range(5):
        ang = rng.uniform(0, np.pi)
        d = np.array([np.cos(ang), np.sin(ang)])
        c0 = rng.uniform(0.2, 0.8, 2)
        line = c0 + np.linspace(-0.5, 0.5, 51)[:, None] * d
        noise = rng.uniform(0, 1, (20, 2))
        p = np.vstack([line, noise])
        w = np.r_[np.ones(51), np.full(20, 0.01)]
        h = _Hough(p, w, 0.02, 0.5)
        votes, c, dirn, key = h.peak()
        assert 51 <= votes <= 51.2 + 1e-9  # every point of the line, in the two bins it straddles
        # (within the two bins' angular reach: 0.04 m over a 1 m line, about 2.3 deg)
        assert abs(float(dirn @ d)) > np.cos(np.radians(2.5)) and np.hypot(*dirn) == pytest.approx(1.0)
        assert float(_line_dist(c0[None], c, dirn)[0]) < 0.02 + 0.005  # the bins' boundary, by the line's middle
        # suppressed: 5 angle bins x 3 distance bins around it (angles wrap round), and the next peak elsewhere
        h.suppress(key)
        ti, ri = key
        nth = h.acc.shape[0]
        around = np.zeros_like(h.suppressed)
        around[np.arange(ti - 2, ti + 3) % nth, max(ri - 1, 0):ri + 2] = True
        np.testing.assert_array_equal(h.suppressed, around)
        nxt = h.peak()
        assert not h.suppressed[nxt[3]] and nxt[0] <= votes
        # removing the line's points leaves the distractors' votes only
        h.remove(np.arange(51))
        np.testing.assert_allclose(h.acc, _Hough(p, np.r_[np.zeros(51), w[51:]], 0.02, 0.5).acc, atol=1e-9)
    # every angle from 0 to 179.5 deg, and the bins cover every point's distance
    h = _Hough(p, w, 0.02, 0.5)
    np.testing.assert_allclose(np.degrees(np.arctan2(h.normals[:, 1], h.normals[:, 0])), np.arange(0, 180, 0.5),
                               atol=1e-9)
    r = (p - p.mean(axis=0)) @ h.normals.T
    assert np.all(np.abs(r) < h.rmax) and h.nr * 0.02 >= 2 * h.rmax
    np.testing.assert_allclose(h.acc.sum(axis=1), w.sum())


def test_chain_runs_at_their_exact_limits():
    """Binary-exact positions (1/8 m cells), every test met with equality: a run stepping exactly run_gap once is
    one run; a line exactly min_line long is a line; pieces exactly join_gap away, exactly as strong as level, exactly
    depth_tol off the line's depth, and of exactly min_columns columns are all taken in. A piece taken by the line
    before it is not taken again by the line after it."""
    c = 0.125

    def piece(start, n, weight=1.0, depth=0.5, skip=None):
        s = start + c * np.arange(n)
        if skip is not None:
            s[skip:] += c  # one step of 2 cells (= run_gap)
        return s, np.full(n, weight), np.full(n, depth)

    parts = [piece(-1.5, 3),  # L2: 0.5 before L
             piece(-0.75, 3, weight=0.5),  # L: 0.5 before A, as strong as level
             piece(0.0, 16, skip=8),  # A: 0 .. 2.0 m, exactly min_line, one 0.25 m step inside
             piece(2.5, 3),  # P: 0.5 after A (and 0.5 before B): min_columns
             piece(3.25, 17),  # B: 3.25 .. 5.25
             piece(5.75, 3, depth=0.75),  # R: 0.5 after B, exactly depth_tol deeper
             piece(6.5, 3)]  # R2: 0.5 after R
    s, w, z = (np.concatenate([p[i] for p in parts]) for i in range(3))
    kw = dict(run_gap=0.25, join_gap=0.5, min_columns=3, min_line=2.0, min_density=0.5, cell=c, level=0.5,
              depth_tol=0.25)
    a, b = _chain_runs(s, w, z, **kw)
    np.testing.assert_array_equal(a, np.arange(0, 3 + 3 + 16 + 3))  # L2, L, A and P
    np.testing.assert_array_equal(b, np.arange(25, len(s)))  # B, R and R2, not P again
