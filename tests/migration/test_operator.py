from dataclasses import replace

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0
from gpr3d.core.grid import Grid3D
from gpr3d.migration.masking import box_mask, image_envelope, masked_migration
from gpr3d.migration.operator import BackProjection, antenna_positions, dot_test, effective_slowness
from gpr3d.simulation.forward import ForwardScene, Sphere, forward_model

RNG = np.random.default_rng(0)
POS = np.c_[RNG.uniform(0, 1, 25), RNG.uniform(0, 1, 25), np.zeros(25)]
YAW = RNG.uniform(-3, 3, 25)
GRID = Grid3D(0, 0, 0.04, 0.05, 0.05, 0.02, 21, 21, 25)


def make(engine, heights=False, air=False, **kw):
    """engine "numba" (SIMD adjoint), "numba-scalar" (the plain numba adjoint) or "numpy"; ``heights``: the ground
    under the antennas 0..5 cm above z = 0; ``air``: every other antenna held 2..30 cm above the ground."""
    pos = POS.copy()
    if heights:
        pos[:, 2] = np.random.default_rng(7).uniform(0, 0.05, len(pos))
    if air:
        kw["air_gap_m"] = np.where(np.arange(len(pos)) % 2 == 0, np.random.default_rng(8).uniform(0.02, 0.3, len(pos)),
                                   0.0)
    tx, rx = antenna_positions(pos, headings_rad=YAW, offset_m=0.1)
    op = BackProjection(GRID, tx, rx, dt_s=0.1e-9, n_samples=200, eps_r=6.0, engine=engine.split("-")[0], **kw)
    op.simd = engine == "numba"
    return op


def clear_of_the_radius(op, margin_m=2e-6):
    """With an aperture radius, no column lies within ``margin_m`` of it from any midpoint: the kernels work the
    distance out in float32 (coordinates of a metre or so: 1e-7 m at worst, FMA or not), the numpy reference in
    float64, so a column that close could fall on either side and differ by its whole value between engines or
    hosts. The geometries used here keep 4 um or more (20 times the margin's own float32 error)."""
    if op.aperture_m is None:
        return True
    mid = 0.5 * (op.tx[:, :2] + op.rx[:, :2])
    X, Y = np.meshgrid(op.grid.x, op.grid.y, indexing="ij")
    d = np.hypot(X[None] - mid[:, 0, None, None], Y[None] - mid[:, 1, None, None])
    return float(np.abs(d - op.aperture_m).min()) > margin_m


def test_the_simd_kernel_builds_here():
    from gpr3d.migration._kernels import simd_adjoint

    assert simd_adjoint() is not None


@pytest.mark.parametrize("engine", ["numba", "numba-scalar", "numpy"])
@pytest.mark.parametrize("kw", [{}, {"aperture_deg": 40}, {"obliquity": True, "spreading": True},
                                {"layers": [(0.0, 4.0), (0.2, 9.0)], "t0_s": 1e-9},
                                {"air": True, "aperture_deg": 40, "obliquity": True, "spreading": True},
                                {"aperture_m": 0.3}, {"air": True, "aperture_deg": 40, "aperture_m": 0.25,
                                                      "obliquity": True}])
def test_dot_test(engine, kw):
    if "layers" in kw:
        kw = dict(kw)
        op = make(engine, **{k: v for k, v in kw.items() if k != "layers"})
        op.slow = effective_slowness(GRID.depth, layers=kw["layers"])
    else:
        op = make(engine, **kw)
    rng = np.random.default_rng(3)
    m = rng.standard_normal(GRID.shape).astype(np.float32)
    d = rng.standard_normal((25, 200)).astype(np.float32)
    fm, fd = op.forward(m).astype(np.float64), op.adjoint(d).astype(np.float64)
    lhs, rhs = float(np.sum(fm * d)), float(np.sum(m * fd))
    # float32 kernels: compare against the sizes of the vectors, not the (cancelling) sums
    assert abs(lhs - rhs) <= 1e-6 * np.linalg.norm(fm) * np.linalg.norm(d)
    assert (lhs, rhs) == pytest.approx(dot_test(op, seed=3))


@pytest.mark.parametrize("engine", ["numba", "numba-scalar"])
@pytest.mark.parametrize("kw", [{}, {"aperture_deg": 40, "obliquity": True}, {"spreading": True},
                                {"obliquity": True}, {"aperture_deg": 30, "obliquity": True, "spreading": True},
                                {"heights": True, "aperture_deg": 40}, {"heights": True, "t0_s": -2e-9},
                                {"air": True}, {"air": True, "heights": True, "aperture_deg": 40, "obliquity": True},
                                {"air": True, "spreading": True}, {"aperture_m": 0.3, "obliquity": True, "spreading": True},
                                {"aperture_deg": 60, "aperture_m": 0.2}, {"air": True, "aperture_m": 0.3}])
def test_numba_matches_numpy_reference(engine, kw):
    a, b = make("numpy", **kw), make(engine, **kw)
    assert clear_of_the_radius(a)
    d = RNG.standard_normal((25, 200)).astype(np.float32)
    ia, ib = a.adjoint(d), b.adjoint(d)
    np.testing.assert_allclose(ib, ia, atol=1e-4 * np.abs(ia).max())
    m = RNG.standard_normal(GRID.shape).astype(np.float32)
    fa, fb = a.forward(m), b.forward(m)
    np.testing.assert_allclose(fb, fa, atol=1e-4 * np.abs(fa).max())


def test_layered_slowness_is_the_vertical_average():
    s = effective_slowness(np.array([0.1, 0.3]), layers=[(0.0, 4.0), (0.2, 16.0)])
    assert s[0] == pytest.approx(2 / C0, rel=1e-9, abs=0)
    assert s[1] == pytest.approx((0.2 * 2 + 0.1 * 4) / 0.3 / C0, rel=1e-9, abs=0)


def test_a_point_scatterer_focuses_at_its_top():
    rng = np.random.default_rng(1)
    n = 400
    pos = np.c_[rng.uniform(0.2, 0.8, n), rng.uniform(0.2, 0.8, n), np.zeros(n)]
    yaw = rng.uniform(-3, 3, n)
    sphere_top = np.array([0.52, 0.47, 0.30])
    r = 0.02
    scene = ForwardScene(eps_r=9.0, spheres=[Sphere((sphere_top[0], sphere_top[1], -sphere_top[2] - r), r)])
    f, dt, ns = 1e9, 0.05e-9, 256
    data = forward_model(scene, pos, headings_rad=yaw, offset_m=0.06, frequency_hz=f, n_samples=ns, dt_s=dt,
                         source_delay_s=0.0)
    grid = Grid3D(0.2, 0.2, 0.1, 0.01, 0.01, 0.005, 61, 61, 61)
    tx, rx = antenna_positions(pos, headings_rad=yaw, offset_m=0.06)
    env = image_envelope(BackProjection(grid, tx, rx, dt_s=dt, n_samples=ns, eps_r=9.0).adjoint(data))
    i, j, k = np.unravel_index(np.argmax(env), env.shape)
    found = np.array([grid.x[i], grid.y[j], grid.depth[k]])
    np.testing.assert_allclose(found, sphere_top, atol=0.011)


def test_mask_and_noise_map_add_up():
    op = make("numba")
    d = RNG.standard_normal((25, 200)).astype(np.float32)
    mask = box_mask(25, 200, 0.1e-9, [[5, 3e-9, 15, 9e-9]], taper_traces=2)
    assert mask[10, 60] == 1.0 and mask[0, 0] == 0.0 and 0 < mask[4, 60] < 1
    sig, noise = masked_migration(op, d, mask)
    np.testing.assert_allclose(sig + noise, op.adjoint(d), atol=1e-4 * np.abs(op.adjoint(d)).max())


def test_envelope_in_slabs_equals_one_transform():
    from scipy.signal import hilbert

    a = np.random.default_rng(5).standard_normal((37, 11, 29)).astype(np.float32)
    want = np.abs(hilbert(a, N=60, axis=2))[:, :, :29]  # padded to 60, the 5-smooth length >= 2 x 29
    np.testing.assert_allclose(image_envelope(a, chunk_voxels=500), want, atol=1e-5)
    np.testing.assert_allclose(image_envelope(a), want, atol=1e-5)


READS = {"gather": (True, True), "loads": (True, False), "scalar": (False, None)}


def scattered_antennas(rng, n, lo, hi, lift, offset=0.1):
    """tx, rx of ``n`` antennas at random over [lo, hi]^2, lifted 0..``lift`` m, headed at random."""
    pos = np.c_[rng.uniform(lo, hi, n), rng.uniform(lo, hi, n), rng.uniform(0, lift, n)]
    return antenna_positions(pos, headings_rad=rng.uniform(-3, 3, n), offset_m=offset)


def _scattered_problem(seed, n, lo, hi, n_samples, max_gap):
    """``n`` antennas scattered over [lo, hi]^2 (:func:`scattered_antennas`), random traces of ``n_samples`` and a
    third of the antennas held 5 cm to ``max_gap`` above the ground: ``(tx, rx, data, gap)``."""
    rng = np.random.default_rng(seed)
    tx, rx = scattered_antennas(rng, n, lo, hi, 0.05)
    d = rng.standard_normal((n, n_samples)).astype(np.float32)
    gap = np.where(rng.uniform(size=n) < 1 / 3, rng.uniform(0.05, max_gap, n), 0.0)
    return tx, rx, d, gap


@pytest.mark.parametrize("radius", [None, 0.3])
@pytest.mark.parametrize("read", list(READS))
def test_tiled_adjoint_sums_what_every_trace_sees(read, radius):
    """With an aperture the adjoint visits, per tile of columns, only the traces whose cone reaches it. Traces
    scattered over 3 m x 3 m around a 1.3 m x 1.1 m grid (most far out of reach, some beyond the grid's edges, some
    lifted, a third held above the ground): the tiled image equals the untiled one and the numpy reference, with
    the SIMD loop reading the trace by hardware gathers or by scalar loads, and with the scalar loop."""
    simd, gather = READS[read]
    n = 300
    tx, rx, d, gap = _scattered_problem(11, n, -1, 2, 200, 0.4)
    grid = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 27, 23, 30)
    kw = dict(dt_s=0.1e-9, n_samples=200, eps_r=6.0, aperture_deg=25, aperture_m=radius, obliquity=True,
              spreading=True, air_gap_m=gap)
    numpy_op = BackProjection(grid, tx, rx, engine="numpy", **kw)
    assert clear_of_the_radius(numpy_op)
    ref = numpy_op.adjoint(d)
    images = {}
    for tiled in (True, False):
        op = BackProjection(grid, tx, rx, **kw)
        op.tiled, op.simd, op.gather = tiled, simd, gather
        images[tiled] = op.adjoint(d)
    peak = np.abs(ref).max()
    np.testing.assert_allclose(images[True], ref, atol=1e-4 * peak)
    np.testing.assert_allclose(images[True], images[False], atol=1e-5 * peak)
    # the scene exercises the culling: a third of the traces lie out of every column's reach
    mid = 0.5 * (tx[:, :2] + rx[:, :2])
    reach = np.tan(np.radians(25)) * grid.depth[-1]
    far = (np.maximum(0, np.maximum(grid.x[0] - mid[:, 0], mid[:, 0] - grid.x[-1])) ** 2
           + np.maximum(0, np.maximum(grid.y[0] - mid[:, 1], mid[:, 1] - grid.y[-1])) ** 2) > reach**2
    assert far.sum() > n // 3


@pytest.mark.parametrize("read", list(READS))
def test_depth_ranges_sum_exactly_what_the_whole_image_has_there(read):
    """Each column summed over its own depths ``[lo, hi)`` only (what coarse-to-fine imaging refines): those voxels
    equal the whole image's (the same terms in the same order; image and fold: to float32 rounding, as fastmath
    lets a voxel fall in a vectorised loop's body or its scalar remainder by where the range starts), every other
    voxel is 0, and a tile of columns with no depths is skipped. The ranges: random per column, some empty, some
    reaching past the grid, a block of tiles with none; a third of the traces held above the ground."""
    simd, gather = READS[read]
    tx, rx, d, gap = _scattered_problem(21, 250, -0.8, 1.8, 220, 0.3)
    rng = np.random.default_rng(22)
    grid = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 25, 22, 37)
    op = BackProjection(grid, tx, rx, dt_s=0.1e-9, n_samples=220, eps_r=6.0, aperture_deg=40, obliquity=True,
                        spreading=True, air_gap_m=gap)
    op.simd, op.gather = simd, gather
    whole, whole_fold = op.adjoint(d, with_fold=True)
    lo = rng.integers(0, 25, grid.shape[:2])
    hi = lo + rng.integers(-3, 40, grid.shape[:2])  # some empty (hi <= lo), some past the last depth
    hi[:16, :8] = 0  # two whole tiles of 8 x 8 columns with nothing to sum
    kr = np.stack([lo, hi], axis=-1)
    img, fold = op.adjoint(d, with_fold=True, depth_range=kr)
    k = np.arange(grid.nd)
    inside = (k >= lo[..., None]) & (k < hi[..., None])
    assert inside.sum() > grid.size // 4 and (~inside).sum() > grid.size // 4
    np.testing.assert_allclose(img[inside], whole[inside], rtol=0, atol=1e-5 * np.abs(whole).max())
    np.testing.assert_allclose(fold[inside], whole_fold[inside], rtol=0, atol=1e-5 * whole_fold.max())
    assert not img[~inside].any() and not fold[~inside].any()
    assert np.abs(whole[~inside]).max() > 0.1 * np.abs(whole).max()  # what was left out is not nothing
    # the numpy engine keeps the same voxels (it migrates everything and drops the rest)
    ref = BackProjection(grid, tx, rx, dt_s=0.1e-9, n_samples=220, eps_r=6.0, aperture_deg=40, obliquity=True,
                         spreading=True, air_gap_m=gap, engine="numpy").adjoint(d, depth_range=kr)
    np.testing.assert_allclose(img, ref, atol=1e-4 * np.abs(ref).max())


def test_depth_ranges_of_the_wrong_shape_are_named():
    rng = np.random.default_rng(1)
    tx, rx = scattered_antennas(rng, 20, 0, 1, 0.05)
    op = BackProjection(Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 6, 5, 8), tx, rx, dt_s=0.1e-9, n_samples=50,
                        eps_r=6.0, aperture_deg=40)
    d = np.zeros((20, 50), np.float32)
    with pytest.raises(InvalidDataError, match=r"depth_range must be \(6, 5, 2\) integers"):
        op.adjoint(d, depth_range=np.zeros((5, 6, 2), int))
    with pytest.raises(InvalidDataError, match="depth_range"):
        op.adjoint(d, depth_range=np.zeros((6, 5, 2)))


@pytest.mark.parametrize("read", list(READS))
@pytest.mark.parametrize("weights", [{}, {"obliquity": True, "spreading": True}])
def test_fold_in_the_same_pass_equals_migrating_a_trace_of_ones(read, weights):
    """The fold summed in the migration's own pass equals the numpy reference's migration of a trace of ones,
    with a record short enough (60 samples) that the deeper voxels fall on its last sample and past its end, where
    the fold must drop to 1 - frac and then 0."""
    rng = np.random.default_rng(2)
    n = 120
    tx, rx = scattered_antennas(rng, n, -0.5, 1.5, 0.05)
    grid = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 21, 19, 30)
    gap = np.where(np.arange(n) % 4 == 0, 0.2, 0.0)  # a quarter held 20 cm above the ground
    kw = dict(dt_s=0.1e-9, n_samples=60, eps_r=6.0, aperture_deg=35, air_gap_m=gap, **weights)
    d = rng.standard_normal((n, 60)).astype(np.float32)
    ref = BackProjection(grid, tx, rx, engine="numpy", **kw)
    want_img, want_fold = ref.adjoint(d), ref.adjoint(np.ones((n, 60), np.float32))
    op = BackProjection(grid, tx, rx, **kw)
    op.simd, op.gather = READS[read]
    img, fold = op.adjoint(d, with_fold=True)
    np.testing.assert_allclose(img, want_img, atol=1e-4 * np.abs(want_img).max())
    np.testing.assert_allclose(fold, want_fold, atol=1e-4 * want_fold.max())
    assert want_fold[..., -1].max() == 0 < want_fold[..., 5].max()  # the record ends inside the grid
    # without an aperture (a second migration) the same
    op2 = BackProjection(grid, tx, rx, **{**kw, "aperture_deg": None})
    i2, f2 = op2.adjoint(d, with_fold=True)
    np.testing.assert_allclose(f2, op2.adjoint(np.ones((n, 60), np.float32)), rtol=1e-6)


def test_read_path_follows_the_cpu_and_the_override(monkeypatch):
    import llvmlite.binding as llb

    from gpr3d.migration import _kernels

    monkeypatch.setenv("GPR3D_GATHER", "0")
    assert _kernels.read_path() == _kernels.LOADS
    monkeypatch.setenv("GPR3D_GATHER", "1")
    assert _kernels.read_path() == _kernels.GATHER
    monkeypatch.delenv("GPR3D_GATHER")
    for cpu, want in (("znver3", _kernels.LOADS), ("znver4", _kernels.LOADS), ("znver5", _kernels.LOADS),
                      ("sapphirerapids", _kernels.GATHER), ("skylake-avx512", _kernels.GATHER)):
        monkeypatch.setattr(llb, "get_host_cpu_name", lambda cpu=cpu: cpu)
        assert _kernels.read_path() == want, cpu


@pytest.mark.parametrize("engine", ["numba", "numpy"])
@pytest.mark.parametrize("aperture", [30, None])
def test_a_window_of_columns_is_that_part_of_the_whole_image(engine, aperture):
    """``window`` migrates only some columns: exactly (bit for bit) those columns of the whole image, fold too."""
    rng = np.random.default_rng(4)
    n = 150
    tx, rx = scattered_antennas(rng, n, -0.3, 1.3, 0.03)
    grid = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 21, 19, 20)
    op = BackProjection(grid, tx, rx, dt_s=0.1e-9, n_samples=120, eps_r=6.0, aperture_deg=aperture,
                        obliquity=True, engine=engine)
    d = rng.standard_normal((n, 120)).astype(np.float32)
    img, fold = op.adjoint(d, with_fold=True)
    wimg, wfold = op.adjoint(d, with_fold=True, window=(3, 11, 8, 19))
    assert wimg.shape == (8, 11, 20)
    np.testing.assert_array_equal(wimg, img[3:11, 8:19])
    np.testing.assert_array_equal(wfold, fold[3:11, 8:19])
    assert np.abs(wimg).max() > 0
    for bad in ((0, 22, 0, 5), (5, 5, 0, 5), (-1, 3, 0, 5)):
        with pytest.raises(InvalidDataError, match="window"):
            op.adjoint(d, window=bad)


@pytest.mark.parametrize("read", list(READS) + ["numpy"])
def test_a_voxel_at_an_antenna_stays_finite(read):
    """A grid from depth 0 with an antenna exactly over a column: that voxel's legs have length 0; the obliquity
    weight must count it as 0 (not 0/0 = NaN, which would spread through the image)."""
    grid = Grid3D(0.0, 0.0, 0.0, 0.05, 1.0, 0.05, 9, 1, 6)
    pos = np.array([[0.2, 0.0, 0.0], [0.3, 0.0, 0.0]])
    tx, rx = antenna_positions(pos, headings_rad=np.zeros(2), offset_m=0.0)
    op = BackProjection(grid, tx, rx, dt_s=0.1e-9, n_samples=40, eps_r=4.0, aperture_deg=45, obliquity=True,
                        engine="numpy" if read == "numpy" else "numba")
    if read != "numpy":
        op.simd, op.gather = READS[read]
    img = op.adjoint(np.ones((2, 40), np.float32))
    assert np.all(np.isfinite(img)) and img.max() > 0
    assert img[4, 0, 0] == 0.0  # the voxel at the antenna at x = 0.2


def test_the_depth_loop_stops_where_the_record_ends():
    """A trace's loop over a column's depths stops past the deepest voxel whose two-way path fits in the record
    (beyond it every read is the zero padding). At zero offset the bound is exact: the cut lies 1-2 indices past
    that voxel; a column wholly in reach runs to the bottom, one out of reach does not run."""
    from gpr3d.migration._kernels import end_depth, record_path

    d0, dd, nd = 0.02, 0.01, 200
    slow = np.full(nd, 1 / 1e8, np.float32)  # 0.1 m/ns
    t0, inv_dt, umax = np.float32(1e-9), np.float32(1e10), np.float32(300.0)  # record: 30 ns, 29 ns after t0
    lmax2 = record_path(slow, 0, t0, inv_dt, umax, np.inf)
    assert lmax2 == pytest.approx((29e-9 * 1e8) ** 2, rel=1e-3)
    # rays partly in air (antennas above the ground) run at up to c: the bound lengthens to c times the record
    assert record_path(slow, 0, t0, inv_dt, umax, np.float32(1 / C0)) == pytest.approx((29e-9 * C0) ** 2, rel=1e-3)
    assert record_path(slow, 0, t0, inv_dt, umax, np.float32(1e-7)) == pytest.approx(lmax2)  # a slower cap: none
    for h in (0.0, 0.5, 1.0, 1.4):
        z_last = np.sqrt(lmax2 / 4 - h * h)  # 2 sqrt(h^2 + z^2) = path
        k_true = int(np.floor((z_last - d0) / dd))
        k1 = end_depth(h, 0.0, h, 0.0, 0.0, 0.0, lmax2, d0, dd, nd)
        assert k_true + 1 <= k1 <= k_true + 2, (h, k_true, k1)
    assert end_depth(0.3, 0.0, 0.3, 0.0, 0.0, 0.0, lmax2, d0, dd, 50) == 50  # the column ends at 0.51 m: all in reach
    assert end_depth(1.5, 0.0, 1.5, 0.0, 0.0, 0.0, lmax2, d0, dd, nd) == 0  # 3 m of path before any depth
    assert record_path(slow, 0, np.float32(31e-9), inv_dt, umax, np.inf) < 0  # a record that ends before time zero


def test_an_antenna_held_above_the_ground_focuses_only_with_its_air_gap():
    """Antennas 0.15 m above ground of eps_r 9 over a sphere whose top is 0.3 m deep: migrated with the air gap
    the image peaks at the top (within a cell and a half); migrated as if the antennas sat on the ground, the
    0.3 m of air taken at c count as 0.05 m of this ground (c/3), and the peak comes out 0.05 m too deep."""
    rng = np.random.default_rng(1)
    n = 400
    pos = np.c_[rng.uniform(0.2, 0.8, n), rng.uniform(0.2, 0.8, n), np.zeros(n)]
    yaw = rng.uniform(-3, 3, n)
    top, r, gap = np.array([0.52, 0.47, 0.30]), 0.02, 0.15
    scene = ForwardScene(eps_r=9.0, spheres=[Sphere((top[0], top[1], -top[2] - r), r)])
    f, dt, ns = 1e9, 0.05e-9, 300
    data = forward_model(scene, pos, headings_rad=yaw, offset_m=0.06, frequency_hz=f, n_samples=ns, dt_s=dt,
                         source_delay_s=0.0, air_gap_m=gap)
    grid = Grid3D(0.2, 0.2, 0.1, 0.01, 0.01, 0.005, 61, 61, 61)
    tx, rx = antenna_positions(pos, headings_rad=yaw, offset_m=0.06)
    found = {}
    for g in (gap, 0.0):
        env = image_envelope(BackProjection(grid, tx, rx, dt_s=dt, n_samples=ns, eps_r=9.0, air_gap_m=g).adjoint(data))
        i, j, k = np.unravel_index(np.argmax(env), env.shape)
        found[g] = np.array([grid.x[i], grid.y[j], grid.depth[k]])
    np.testing.assert_allclose(found[gap], top, atol=0.015)
    assert found[0.0][2] == pytest.approx(top[2] + 0.05, abs=0.015)


@pytest.mark.parametrize("read", list(READS))
@pytest.mark.parametrize("aperture", [None, 40.0])
def test_voxels_on_the_surface_under_an_air_gap(read, aperture):
    """A grid whose first depth is the surface itself, antennas 0.2 m up: each leg runs all in the air to those
    voxels (a refracted ray with no ground part); every engine stays finite and agrees with the numpy reference
    (a 0/0 in the Newton step once made NaN sample indices here, and a crash)."""
    rng = np.random.default_rng(4)
    tx, rx = scattered_antennas(rng, 40, 0.0, 1.0, 0.0)
    grid = Grid3D(0.0, 0.0, 0.0, 0.05, 0.05, 0.01, 21, 21, 30)
    kw = dict(dt_s=0.05e-9, n_samples=200, eps_r=6.0, aperture_deg=aperture, obliquity=True, air_gap_m=0.2)
    d = rng.standard_normal((40, 200)).astype(np.float32)
    ref = BackProjection(grid, tx, rx, engine="numpy", **kw).adjoint(d)
    op = BackProjection(grid, tx, rx, **kw)
    op.simd, op.gather = READS[read]
    img = op.adjoint(d)
    assert np.all(np.isfinite(img))
    np.testing.assert_allclose(img, ref, atol=1e-4 * np.abs(ref).max())


def test_on_grid_keeps_everything_but_the_columns_and_refuses_another_depth_axis():
    rng = np.random.default_rng(4)
    tx, rx = scattered_antennas(rng, 30, 0, 1, 0.05)
    g = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 8, 7, 10)
    op = BackProjection(g, tx, rx, dt_s=0.1e-9, n_samples=80, eps_r=6.0, aperture_deg=40, obliquity=True)
    coarse = replace(g, dx=0.1, dy=0.15, nx=4, ny=3)
    sub = op.on_grid(coarse)
    np.testing.assert_array_equal(sub.x, coarse.x)
    np.testing.assert_array_equal(sub.y, coarse.y)
    assert sub.grid == coarse and op.grid == g and sub.tan_ap == op.tan_ap and sub.obliquity
    d = rng.standard_normal((30, 80)).astype(np.float32)
    want = BackProjection(coarse, tx, rx, dt_s=0.1e-9, n_samples=80, eps_r=6.0, aperture_deg=40,
                          obliquity=True).adjoint(d)
    np.testing.assert_array_equal(sub.adjoint(d), want)
    for bad in (replace(g, nd=9), replace(g, dd=0.03), replace(g, d0=0.02)):
        with pytest.raises(InvalidDataError, match=r"^on_grid keeps the depth axis: the grid must have the same d0, "
                                                   r"dd and nd$"):
            op.on_grid(bad)


def test_the_tiled_adjoint_lets_other_threads_run_while_it_sums():
    """Live mode reads its source in a thread beside the migration: the tiled kernel runs without Python's lock
    (``nogil``). A thread that notes the time every half millisecond, while the main thread migrates for a few tenths
    of a second: held, it would note next to nothing between the kernel's start and end (Python hands its lock over every
    5 ms, but compiled code never offers it)."""
    import threading
    import time

    rng = np.random.default_rng(3)
    tx, rx = scattered_antennas(rng, 4000, 0.0, 2.0, 0.05)
    d = rng.standard_normal((4000, 400)).astype(np.float32)
    grid = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 100, 100, 80)
    op = BackProjection(grid, tx, rx, dt_s=0.1e-9, n_samples=400, eps_r=6.0, aperture_deg=45)
    assert op.tiled
    BackProjection(grid, tx[:10], rx[:10], dt_s=0.1e-9, n_samples=400, eps_r=6.0, aperture_deg=45).adjoint(d[:10])
    # (compiled or loaded before the clock starts)
    marks, stop = [], threading.Event()

    def note():
        while not stop.is_set():
            marks.append(time.perf_counter())
            time.sleep(0.0005)

    th = threading.Thread(target=note)
    th.start()
    calls = []
    try:
        time.sleep(0.02)
        while sum(b - a for a, b in calls) < 0.3 and len(calls) < 50:  # (a few tenths of a second on any CPU)
            t0 = time.perf_counter()
            op.adjoint(d)
            calls.append((t0, time.perf_counter()))
    finally:
        stop.set()
        th.join()
    inside = [m for m in marks if any(a + 0.01 < m < b - 0.01 for a, b in calls)]
    assert len(inside) > 50, (calls, len(inside))


@pytest.mark.parametrize("engine", ["numba", "numba-scalar", "numba-untiled", "numba-scalar-untiled", "numpy"])
def test_an_aperture_radius_keeps_exactly_the_columns_within_it_of_each_midpoint(engine):
    """``aperture_m``: a trace adds to a column at every depth its cone reaches when the column lies within the
    radius of the trace's tx-rx midpoint, and nothing beyond it. Each trace migrated alone, with and without the
    radius: the two images agree on the columns within it (distances worked out here) and the capped one is zero
    elsewhere; the radius is the narrower limit on some columns and the cone on others."""
    grid = Grid3D(0.0, 0.0, 0.0, 0.04, 0.04, 0.03, 26, 24, 30)
    pos = np.array([[0.5, 0.45, 0.0], [0.2, 0.7, 0.0], [0.9, 0.1, 0.0]])
    tx, rx = antenna_positions(pos, headings_rad=np.array([0.0, 1.0, -2.0]), offset_m=0.1)
    rng = np.random.default_rng(2)
    d = rng.standard_normal((3, 200)).astype(np.float32)
    X, Y = np.meshgrid(grid.x, grid.y, indexing="ij")
    for j in range(3):
        ops = []
        for radius in (None, 0.27):
            op = BackProjection(grid, tx[j:j + 1], rx[j:j + 1], dt_s=0.1e-9, n_samples=200, eps_r=6.0,
                                aperture_deg=60, aperture_m=radius, obliquity=True, engine=engine.split("-")[0])
            op.simd, op.tiled = "scalar" not in engine, "untiled" not in engine
            ops.append(op.adjoint(d[j:j + 1]))
        # one trace: each voxel holds one term, so the two agree to rounding whatever order the kernels sum in
        full, capped = ops
        mx, my = 0.5 * (tx[j, :2] + rx[j, :2])
        inside = np.hypot(X - mx, Y - my) <= 0.27
        assert inside.sum() > 50 and (~inside & (np.abs(full).max(axis=2) > 0)).sum() > 100
        peak = np.abs(full).max()
        np.testing.assert_allclose(capped[inside], full[inside], rtol=0, atol=1e-6 * peak)
        assert np.all(capped[~inside] == 0)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "1", True])
def test_an_aperture_radius_that_is_not_a_positive_length_is_named(bad):
    tx, rx = antenna_positions(POS, headings_rad=YAW, offset_m=0.1)
    with pytest.raises(InvalidDataError, match=r"^aperture_m must be a positive number of metres"):
        BackProjection(GRID, tx, rx, dt_s=0.1e-9, n_samples=200, eps_r=6.0, aperture_m=bad)
