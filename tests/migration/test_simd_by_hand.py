"""The explicit-SIMD depth loop by hand: each intrinsic (four weight modes, with and without the fold, both ways of
reading the trace) is built afresh in the test and run on one trace, and every depth's sum is compared with the
formula evaluated here in float64: the two legs, the time, the clamp, linear interpolation between neighbouring
samples, the weights, the fold of a trace of ones, the aperture's first depth and the untouched blocks.

The intrinsics are built inside each test (their cache emptied, a new jitted caller made) so that a change to the
code generation shows here and is not hidden by a kernel that an earlier test or numba's disk cache compiled.
"""

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from gpr3d.migration import _simd  # noqa: E402

W = _simd.W


def build(monkeypatch, weights, fold):
    monkeypatch.setattr(_simd, "_STACKS", {})
    st = _simd.stack(weights, fold)
    assert _simd.stack(weights, fold) is st and set(_simd._STACKS) == {(weights, fold)}
    if fold:
        @numba.njit
        def run(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather):
            st(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather)
    else:
        @numba.njit
        def run(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather):
            st(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, gather)
    return run


#: float32 times of about 100 samples carry rounding of some 1e-5 samples, and the trace changes by up to ~3 a
#: sample: sums agree to about 1e-4 (a wrong formula is off by far more)
def reference(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, weights):
    """The sums in float64, one depth at a time."""
    acc, facc = acc.astype(np.float64), (None if facc is None else facc.astype(np.float64))
    for k in range((k0 // W) * W, nblk * W):
        if k < k0:
            continue
        za, zb = depth[k] + ha, depth[k] + hb
        ra, rb = np.sqrt(h2a + za * za), np.sqrt(h2b + zb * zb)
        u = min(max((t0 + (ra + rb) * slow[k]) * inv_dt, 0.0), umax)
        i0 = int(np.floor(u))
        frac = u - i0
        val = row[i0] + frac * (row[i0 + 1] - row[i0])
        w = 1.0
        if weights & 1:
            w *= 0.5 * (za / max(ra, 1e-12) + zb / max(rb, 1e-12))
        if weights & 2:
            w *= 0.5 * (ra + rb)
        acc[k] += w * val
        if facc is not None:
            facc[k] += w * min(max(umax - u, 0.0), 1.0)
    return acc, facc


def problem(n_samples=120, n_blocks=3, seed=8):
    rng = np.random.default_rng(seed)  # the same problem whichever tests run, in whatever order
    row = np.zeros(n_samples + 2, np.float32)
    row[:n_samples] = rng.standard_normal(n_samples)
    depth = (0.02 + 0.015 * np.arange(n_blocks * W)).astype(np.float32)
    slow = np.full(n_blocks * W, 1 / 1.2e8, np.float32)
    slow[W:] *= 1.1  # a slower layer from the second block down
    acc = rng.standard_normal(n_blocks * W).astype(np.float32)  # sums already there: added to
    facc = rng.random(n_blocks * W).astype(np.float32)
    return row, depth, slow, acc, facc


@pytest.mark.parametrize("fold", [False, True])
@pytest.mark.parametrize("weights", [0, 1, 2, 3])
def test_each_intrinsic_sums_what_the_formula_gives(monkeypatch, weights, fold):
    run = build(monkeypatch, weights, fold)
    row, depth, slow, acc0, facc0 = problem()
    # tx 5 cm to one side and 2 cm up, rx 7 cm to the other side on the ground; 0.1 ns samples; times that run
    # past the trace's end for the deepest voxels (the clamp and the zero pair)
    scal = dict(h2a=np.float32(0.05 ** 2), h2b=np.float32(0.07 ** 2), ha=np.float32(0.02), hb=np.float32(0.0),
                t0=np.float32(0.3e-9), inv_dt=np.float32(1e10), umax=np.float32(120.0))
    for k0, nblk in [(20, 3), (0, 3), (16, 2), (37, 3)]:
        for gather in (1, 0):
            acc, facc = acc0.copy(), facc0.copy()
            args = (row, depth, slow, acc) + ((facc,) if fold else ()) + tuple(scal.values()) + (k0, nblk, gather)
            run(*args)
            want_acc, want_facc = reference(row, depth.astype(np.float64), slow.astype(np.float64), acc0,
                                            facc0 if fold else None, *[float(v) for v in scal.values()], k0, nblk,
                                            weights)
            np.testing.assert_allclose(acc, want_acc, rtol=1e-4, atol=2e-4, err_msg=f"k0 {k0} nblk {nblk} g {gather}")
            # depths before the first live one and blocks past nblk are left exactly as they were
            untouched = np.r_[np.arange(0, k0), np.arange(nblk * W, 3 * W)]
            np.testing.assert_array_equal(acc[untouched], acc0[untouched])
            assert not np.array_equal(acc, acc0)
            if fold:
                np.testing.assert_allclose(facc, want_facc, rtol=1e-4, atol=2e-4)
                np.testing.assert_array_equal(facc[untouched], facc0[untouched])
            else:
                np.testing.assert_array_equal(facc, facc0)


def test_the_reference_reaches_every_branch():
    """The problem above covers what the kernel must get right: times before the trace (clamped to 0), inside it,
    on its last stretch (interpolated towards the zero pair) and past it (clamped to umax); a fold below one."""
    row, depth, slow, acc, facc = problem()
    za, zb = depth.astype(np.float64) + 0.02, depth.astype(np.float64)
    u = (0.3e-9 + (np.hypot(0.05, za) + np.hypot(0.07, zb)) * slow) * 1e10
    assert u.min() < 120 and u.max() > 120
    assert np.any((u > 119) & (u < 120))
    _, f = reference(row, depth, slow, acc, np.zeros_like(facc), 0.05 ** 2, 0.07 ** 2, 0.02, 0.0, 0.3e-9, 1e10,
                     120.0, 0, 3, 0)
    assert f.min() == 0.0 and f.max() == 1.0 and np.any((f > 0) & (f < 1))
    # and times before the trace start: a large negative t0
    u0 = (-5e-9 + (np.hypot(0.05, za) + np.hypot(0.07, zb)) * slow) * 1e10
    assert u0.min() < 0 < u0.max()


@pytest.mark.parametrize("gather", [1, 0])
def test_times_before_the_trace_read_its_first_sample(monkeypatch, gather):
    run = build(monkeypatch, 0, True)
    row, depth, slow, acc0, facc0 = problem()
    acc, facc = acc0.copy(), facc0.copy()
    scal = (np.float32(0.05 ** 2), np.float32(0.07 ** 2), np.float32(0.02), np.float32(0.0), np.float32(-5e-9),
            np.float32(1e10), np.float32(120.0))
    run(row, depth, slow, acc, facc, *scal, 0, 3, gather)
    want_acc, want_facc = reference(row, depth, slow, acc0, facc0, *[float(v) for v in scal], 0, 3, 0)
    np.testing.assert_allclose(acc, want_acc, rtol=1e-4, atol=2e-4)
    np.testing.assert_allclose(facc, want_facc, rtol=1e-4, atol=2e-4)


def test_a_voxel_at_an_antenna_has_no_obliquity_not_nan(monkeypatch):
    """Both antennas on the voxel (no offset, depth 0): r = 0, and the cosine counts as 0 instead of 0/0."""
    run = build(monkeypatch, 1, True)
    row, depth, slow, acc0, facc0 = problem()
    depth[:] = np.linspace(0.0, 0.3, depth.size)
    acc, facc = acc0.copy(), facc0.copy()
    scal = (np.float32(0.0), np.float32(0.0), np.float32(0.0), np.float32(0.0), np.float32(0.0), np.float32(1e10),
            np.float32(120.0))
    run(row, depth, slow, acc, facc, *scal, 0, 3, 1)
    assert np.isfinite(acc).all() and np.isfinite(facc).all()
    assert acc[0] == acc0[0] and facc[0] == facc0[0]
    want_acc, want_facc = reference(row, depth, slow, acc0, facc0, *[float(v) for v in scal], 0, 3, 1)
    np.testing.assert_allclose(acc, want_acc, rtol=1e-4, atol=2e-4)
    np.testing.assert_allclose(facc, want_facc, rtol=1e-4, atol=2e-4)


def test_without_the_fold_by_default(monkeypatch):
    monkeypatch.setattr(_simd, "_STACKS", {})
    assert _simd.stack(2) is _simd.stack(2, False) and set(_simd._STACKS) == {(2, False)}
