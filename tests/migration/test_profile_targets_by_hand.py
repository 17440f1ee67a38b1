"""Targets in one migrated profile (extract_profile_targets) on envelopes drawn in the test: a flat reflector, a
blob off the grid's cells, a steep flank, weak and narrow parts, the depth cut, and the order."""

import numpy as np
import pytest

from gpr3d.migration.targets import extract_profile_targets

ALONG = np.arange(60) * 0.01
DEPTH = np.arange(40) * 0.005


def _blob(env, a0, d0, amp, sa=0.01, sd=0.008):
    A, D = np.meshgrid(ALONG, DEPTH, indexing="ij")
    g = amp * np.exp(-0.5 * (((A - a0) / sa) ** 2 + ((D - d0) / sd) ** 2))
    env += np.where(g > 0.05 * amp, g, 0.0)


def _vertex(y0, y1, y2):
    """The parabola's vertex through three samples, in cells from the middle one."""
    return 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)


def _scene():
    env = np.zeros((len(ALONG), len(DEPTH)), np.float32)
    env[5:45, 20] = 1.0  # a flat reflector at 0.1 m from 0.05 to 0.44 m
    env[5:45, 19] = env[5:45, 21] = 0.5
    _blob(env, 0.5235, 0.0612, 0.9)  # a pipe crossing the profile
    return env


def test_a_flat_reflector_and_a_crossing_pipe_by_hand():
    env = _scene()
    out = extract_profile_targets(env, ALONG, DEPTH)
    peak = np.percentile(env.max(axis=1), 99.5)
    assert peak == pytest.approx(1.0)
    assert [t.kind for t in out] == ["line", "point"]  # ordered by score x columns: 40 strong columns first
    line, pt = out
    np.testing.assert_allclose(line.points_xyz, [[0.05, 0.0, 0.1], [0.44, 0.0, 0.1]], atol=1e-9)
    assert line.depth_m == pytest.approx(0.1, abs=1e-9)
    assert line.score == pytest.approx(1.0 / peak) and line.n_voxels == 40 and line.extra == {"profile": True}
    # the point: the blob's brightest cell, moved by the parabolas through its neighbours along and down
    i, k = np.unravel_index(np.argmax(np.where(ALONG[:, None] > 0.47, env, 0)), env.shape)
    a = ALONG[i] + 0.01 * _vertex(env[i - 1, k], env[i, k], env[i + 1, k])
    d = DEPTH[k] + 0.005 * _vertex(env[i, k - 1], env[i, k], env[i, k + 1])
    np.testing.assert_allclose(pt.points_xyz, [[a, 0.0, d]], atol=1e-6)
    assert abs(a - 0.5235) < 0.002 and abs(d - 0.0612) < 0.002  # and near the blob's true centre
    assert pt.depth_m == pytest.approx(d, abs=1e-6) and pt.score == pytest.approx(env[i, k] / peak)
    assert pt.extra == {"profile": True} and pt.n_voxels == len(np.unique(np.nonzero(env[47:, :] >= 0.3)[0]))


def test_the_depth_cut_weak_and_narrow_parts_and_the_line_contrast():
    env = _scene()
    # the depth cut keeps the depths from it down: the pipe at 0.06 m goes, the reflector at 0.1 m stays; a hair
    # deeper, the reflector's upper flank at 0.105 m is what is left of it
    cut = extract_profile_targets(env, ALONG, DEPTH, min_depth_m=0.1)
    assert [(t.kind, round(t.depth_m, 6)) for t in cut] == [("line", 0.1)]
    cut = extract_profile_targets(env, ALONG, DEPTH, min_depth_m=0.1 + 2e-9)
    assert [(t.kind, round(t.depth_m, 6)) for t in cut] == [("line", 0.105)]
    # threshold 0.3 of the reference: a part at 0.29 is no target, one at 0.31 is
    for amp, n in ((0.29, 2), (0.31, 3)):
        e = env.copy()
        e[50:53, 35] = amp
        assert len(extract_profile_targets(e, ALONG, DEPTH)) == n, amp
    # a part of one column is dropped, one of two columns is a point
    for width, n in ((1, 2), (2, 3)):
        e = env.copy()
        e[50:50 + width, 35] = 0.8
        assert len(extract_profile_targets(e, ALONG, DEPTH)) == n, width
    # a long part whose columns average under 4/3 of the threshold is a point, over it a line
    for amp, kind in ((0.38, "point"), (0.42, "line")):
        e = np.zeros_like(env)
        e[5:45, 20] = 1.0
        e[5:45, 30] = amp
        kinds = sorted(t.kind for t in extract_profile_targets(e, ALONG, DEPTH))
        assert kinds == sorted(["line", kind]), amp


def test_a_steep_flank_is_a_point_and_a_short_line_is_a_point():
    env = np.zeros((len(ALONG), len(DEPTH)), np.float32)
    for j in range(36):  # 0.025 m deeper per 0.01 m along (68 deg): a hyperbola's flank
        env[10 + j // 5, 2 + j] = 1.0
    kinds = [t.kind for t in extract_profile_targets(env, ALONG, DEPTH)]
    assert kinds and "line" not in kinds
    short = np.zeros_like(env)
    short[5:34, 20] = 1.0  # 0.28 m: under the 0.3 m of a line
    assert [t.kind for t in extract_profile_targets(short, ALONG, DEPTH)] == ["point"]
    short[5:35, 20] = 1.0  # 0.29 m ... and 0.30 m
    assert [t.kind for t in extract_profile_targets(short, ALONG, DEPTH)] == ["point"]
    short[5:36, 20] = 1.0
    assert [t.kind for t in extract_profile_targets(short, ALONG, DEPTH)] == ["line"]


def test_profile_targets_refuse_a_mismatched_envelope_and_keep_empty_ones_empty():
    with pytest.raises(ValueError, match=r"^envelope \(60, 39\) does not match 60 positions x 40 depths$"):
        extract_profile_targets(np.zeros((60, 39)), ALONG, DEPTH)
    with pytest.raises(ValueError, match=r"^envelope \(60,\) does not match"):
        extract_profile_targets(np.zeros(60), ALONG, DEPTH)
    assert extract_profile_targets(np.zeros((60, 40)), ALONG, DEPTH) == []
    # parts whose brightest cell is at the image's corners: points there, with no neighbours to refine by
    e = np.zeros((60, 40), np.float32)
    e[0, 0], e[1, 0] = 1.0, 0.9
    e[59, 39], e[58, 39] = 1.0, 0.9
    pts = extract_profile_targets(e, ALONG, DEPTH)
    assert sorted(p.points_xyz[0] for p in pts) == [[0.0, 0.0, 0.0], [0.59, 0.0, 0.195]]
