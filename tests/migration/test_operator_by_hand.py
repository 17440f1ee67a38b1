"""The 3D back projection against sums written out in the test: the default operator (no weights, no aperture),
a two-layer velocity, the cone's edge, the window's bounds, the environment switches and the output types."""

import math

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.migration.operator import BackProjection, antenna_positions

C = 299792458.0


def _geometry(seed=0, n=7, ns=80):
    rng = np.random.default_rng(seed)
    grid = Grid3D(0.0, 0.0, 0.02, 0.03, 0.04, 0.015, 5, 4, 9)
    tx = np.c_[rng.uniform(-0.05, 0.2, n), rng.uniform(-0.05, 0.2, n), rng.uniform(-0.02, 0.02, n)]
    rx = tx + np.c_[rng.uniform(-0.05, 0.05, (n, 2)), np.zeros(n)]
    data = rng.standard_normal((n, ns)).astype(np.float32)
    return grid, tx, rx, data


def _vertical_time(d, layers):
    """Vertical one-way time from the surface down to depth d through ``layers`` [(top, eps_r), ...]."""
    t = 0.0
    for i, (top, eps) in enumerate(layers):
        bottom = layers[i + 1][0] if i + 1 < len(layers) else math.inf
        t += max(0.0, min(bottom, d) - top) * math.sqrt(eps) / C
    return t


def _adjoint_by_hand(grid, tx, rx, data, dt, t0, layers):
    """Each voxel gathers each trace at t0 + (|a - p| + |p - b|) / v_eff(d), v_eff the vertical average down to d
    (the antennas' z is the ground's elevation above the voxel's depth datum), linear interpolation, zero past the
    record; unit weights."""
    n, ns = data.shape
    img = np.zeros(grid.shape)
    for i, x in enumerate(grid.x):
        for j, y in enumerate(grid.y):
            for k, d in enumerate(grid.depth):
                slow = _vertical_time(d, layers) / d
                for m in range(n):
                    ra = math.sqrt((x - tx[m, 0]) ** 2 + (y - tx[m, 1]) ** 2 + (d + tx[m, 2]) ** 2)
                    rb = math.sqrt((x - rx[m, 0]) ** 2 + (y - rx[m, 1]) ** 2 + (d + rx[m, 2]) ** 2)
                    u = (t0 + (ra + rb) * slow) / dt
                    i0 = math.floor(u)
                    if 0 <= i0 < ns:
                        nxt = data[m, i0 + 1] if i0 + 1 < ns else 0.0
                        img[i, j, k] += data[m, i0] + (u - i0) * (nxt - data[m, i0])
    return img


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_the_default_operator_is_an_unweighted_stack_and_honours_layers(engine):
    grid, tx, rx, data = _geometry()
    layers = [(0.0, 4.0), (0.07, 12.0)]
    dt, t0 = 0.05e-9, 0.3e-9
    op = BackProjection(grid, tx, rx, dt_s=dt, n_samples=data.shape[1], t0_s=t0, layers=layers, engine=engine)
    ref = _adjoint_by_hand(grid, tx, rx, data, dt, t0, layers)
    img = op.adjoint(data)
    assert img.dtype == np.float32
    np.testing.assert_allclose(img, ref, atol=2e-3 * np.abs(ref).max())
    out = op.forward(img)
    assert out.dtype == np.float32 and out.shape == data.shape
    # and the constant velocity of eps_r 4 is the first layer alone
    one = BackProjection(grid, tx, rx, dt_s=dt, n_samples=data.shape[1], t0_s=t0, eps_r=4.0, engine=engine)
    np.testing.assert_allclose(one.adjoint(data), _adjoint_by_hand(grid, tx, rx, data, dt, t0, [(0.0, 4.0)]),
                               atol=2e-3 * np.abs(ref).max())


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_the_fold_comes_back_as_float32(engine):
    grid, tx, rx, data = _geometry(n=3)
    for ap in (None, 40.0):
        op = BackProjection(grid, tx, rx, dt_s=0.05e-9, n_samples=data.shape[1], eps_r=6.0, aperture_deg=ap,
                            engine=engine)
        img, fold = op.adjoint(data, with_fold=True)
        assert img.dtype == np.float32 and fold.dtype == np.float32 and fold.shape == grid.shape
        np.testing.assert_allclose(fold, op.adjoint(np.ones_like(data)), rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_a_voxel_on_the_cone_edge_is_inside_the_aperture(engine):
    """45 deg: a voxel 2 cells down and 2 cells aside lies on the cone (tan 45 deg is 1 less an ulp, so hm / tan
    is a hair over 2 cells): it counts, the one above it does not."""
    grid = Grid3D(0.0, 0.0, 0.0, 0.01, 0.01, 0.01, 3, 1, 4)
    tx = rx = np.array([[0.0, 0.0, 0.0]])
    data = np.ones((1, 50), np.float32)
    op = BackProjection(grid, tx, rx, dt_s=0.01e-9, n_samples=50, eps_r=1.0, aperture_deg=45.0, engine=engine)
    img = op.adjoint(data)
    assert img[2, 0, 2] == pytest.approx(1.0) and img[2, 0, 1] == 0.0
    assert img[1, 0, 1] == pytest.approx(1.0) and img[1, 0, 0] == 0.0


def test_antennas_without_an_offset_sit_at_the_position():
    p = np.array([[1.0, 2.0, 0.1], [1.5, 2.0, 0.0]])
    tx, rx = antenna_positions(p)
    np.testing.assert_array_equal(tx, p)
    np.testing.assert_array_equal(rx, p)


def test_an_air_gap_table_of_two_axes_is_refused():
    grid, tx, rx, data = _geometry(n=3)
    with pytest.raises(InvalidDataError, match=r"^air_gap_m must be one number or one per trace \(3\), got shape "
                                               r"\(3, 1\)$"):
        BackProjection(grid, tx, rx, dt_s=1e-10, n_samples=10, eps_r=4.0, air_gap_m=np.zeros((3, 1)))


def test_windows_at_the_grid_edges_are_taken_and_empty_ones_refused():
    grid, tx, rx, data = _geometry(n=3)
    op = BackProjection(grid, tx, rx, dt_s=0.05e-9, n_samples=data.shape[1], eps_r=6.0)
    whole = op.adjoint(data)
    np.testing.assert_array_equal(op.adjoint(data, window=(0, grid.nx, 0, grid.ny)), whole)
    np.testing.assert_array_equal(op.adjoint(data, window=(0, 1, 0, 1)), whole[:1, :1])
    for bad in [(0, grid.nx, 2, 2), (3, 3, 0, 1), (-1, 2, 0, 1), (0, grid.nx + 1, 0, 1), (0, 1, 0, grid.ny + 1)]:
        with pytest.raises(InvalidDataError, match=r"^window .* does not lie inside the 5 x 4 columns of the grid$"):
            op.adjoint(data, window=bad)


@pytest.mark.parametrize("name, attr", [("GPR3D_SIMD", "simd"), ("GPR3D_TILED", "tiled")])
def test_the_kernel_switches_read_the_environment(monkeypatch, name, attr):
    grid, tx, rx, _ = _geometry(n=2)

    def made():
        return getattr(BackProjection(grid, tx, rx, dt_s=1e-10, n_samples=10, eps_r=4.0), attr)

    monkeypatch.delenv(name, raising=False)
    assert made() is True
    monkeypatch.setenv(name, "0")
    assert made() is False
    monkeypatch.setenv(name, "1")
    assert made() is True
    monkeypatch.setenv(name.lower(), "0")  # the name is upper case only
    assert made() is True


def test_only_the_kernel_that_runs_is_built(monkeypatch):
    """Building a kernel costs seconds on a machine's first run: with an aperture only the tiled kernel is asked
    for (with the SIMD loop, or the scalar one where that does not build), without one only the untiled SIMD
    kernel (or the scalar one where it does not build); the image is the reference's each time."""
    from gpr3d.migration import _kernels

    grid, tx, rx, data = _geometry(3)
    asked = []
    real_tiled, real_simd = _kernels.tiled_adjoint, _kernels.simd_adjoint

    def tiled(path, fold=False, _ok=True):
        asked.append(("tiled", path, fold))
        return real_tiled(path, fold) if _ok or path == 0 else None

    def simd(path=_kernels.GATHER, _ok=True):
        asked.append(("simd", path))
        return real_simd(path) if _ok else None

    monkeypatch.setattr(_kernels, "tiled_adjoint", tiled)
    monkeypatch.setattr(_kernels, "simd_adjoint", simd)
    monkeypatch.setattr(_kernels, "read_path", lambda: _kernels.LOADS)
    for aperture in (40.0, None):
        op = BackProjection(grid, tx, rx, dt_s=1e-10, n_samples=data.shape[1], eps_r=5.0, aperture_deg=aperture)
        ref = op._adjoint_numpy(data)
        asked.clear()
        img = op.adjoint(data)
        assert asked == ([("tiled", _kernels.LOADS, False)] if aperture else [("simd", _kernels.LOADS)])
        np.testing.assert_allclose(img, ref, atol=1e-4 * float(np.abs(ref).max()))
        # the SIMD loop does not build here: the scalar depth loop, in the same kernel family
        monkeypatch.setattr(_kernels, "tiled_adjoint", lambda p, f=False: tiled(p, f, _ok=False))
        monkeypatch.setattr(_kernels, "simd_adjoint", lambda p=_kernels.GATHER: simd(p, _ok=False))
        asked.clear()
        img2 = op.adjoint(data)
        assert asked == ([("tiled", _kernels.LOADS, False), ("tiled", 0, False)] if aperture
                         else [("simd", _kernels.LOADS)])
        np.testing.assert_allclose(img2, img, atol=1e-4 * float(np.abs(img).max()))
        op.simd = False  # GPR3D_SIMD=0: the SIMD loop is never asked for
        asked.clear()
        op.adjoint(data)
        assert asked == ([("tiled", 0, False)] if aperture else [])
        monkeypatch.setattr(_kernels, "tiled_adjoint", tiled)
        monkeypatch.setattr(_kernels, "simd_adjoint", simd)
