"""2D reverse-time migration: focusing against analytic travel times (straight rays, and Fermat's principle through a
layer boundary), absorbing edges, and one-line errors."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from scipy.signal import hilbert

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0
from gpr3d.migration.rtm import _run, _sponge, eps_column, rtm_bscan

F = 800e6
DT = 20e-12
T0 = 1.5 / F  # the pulse peaks this long after the first sample


def ricker(t, f=F):
    a = (math.pi * f * t) ** 2
    return (1 - 2 * a) * np.exp(-a)


def bscan(twt_s):
    """Zero-offset traces with a Ricker pulse at the two-way times ``twt_s`` (one per trace), 600 samples."""
    t = np.arange(600) * DT
    return ricker(t[None, :] - T0 - np.asarray(twt_s)[:, None])


def focus(r):
    env = np.abs(hilbert(r.image, axis=1))
    i, k = np.unravel_index(int(np.argmax(env)), env.shape)
    return r.x_m[i], r.depth_m[k]


def two_layer_twt(x, xp, zp, top, v1, v2):
    """Two-way time from the surface at ``x`` to a point (xp, zp) below a boundary at depth ``top``: the fastest
    path through the boundary (Fermat's principle, refraction found numerically)."""
    def one_way(xi):
        return math.hypot(xi - x, top) / v1 + math.hypot(xp - xi, zp - top) / v2

    lo, hi = min(x, xp), max(x, xp)
    if hi - lo < 1e-9:
        return 2 * one_way(x)
    return 2 * minimize_scalar(one_way, bounds=(lo, hi), method="bounded", options={"xatol": 1e-9}).fun


def test_a_point_diffractor_focuses_where_it_is():
    eps = 6.0
    v = C0 / math.sqrt(eps)
    x = np.arange(0.0, 1.2, 0.01)
    xp, zp = 0.55, 0.35
    r = rtm_bscan(bscan(2 * np.hypot(x - xp, zp) / v), x, DT, frequency_hz=F, depth_m=0.7, eps_r=eps, t0_s=T0)
    fx, fz = focus(r)
    assert abs(fx - xp) <= 1.5 * r.cell_m and abs(fz - zp) <= 2.5 * r.cell_m, (fx, fz, r.cell_m)
    # a wrong velocity focuses elsewhere: the test can tell
    r2 = rtm_bscan(bscan(2 * np.hypot(x - xp, zp) / v), x, DT, frequency_hz=F, depth_m=0.7, eps_r=9.0, t0_s=T0)
    assert abs(focus(r2)[1] - zp) > 0.04


def test_layers_refract_the_back_propagated_field():
    """A point 15 cm below a boundary (eps 4 over eps 12): with the layers RTM focuses on it; with one average
    velocity it does not. The data's times follow Fermat's principle through the boundary."""
    top, xp, zp = 0.2, 0.6, 0.35
    v1, v2 = C0 / 2.0, C0 / math.sqrt(12.0)
    x = np.arange(0.0, 1.2, 0.01)
    d = bscan([two_layer_twt(xi, xp, zp, top, v1, v2) for xi in x])
    layers = [(0.0, 4.0), (top, 12.0)]
    r = rtm_bscan(d, x, DT, frequency_hz=F, depth_m=0.6, layers=layers, t0_s=T0)
    fx, fz = focus(r)
    assert abs(fx - xp) <= 1.5 * r.cell_m and abs(fz - zp) <= 3 * r.cell_m, (fx, fz, r.cell_m)
    # one velocity with the same vertical time down to the point: the hyperbola's shape is wrong, the focus blurred
    eps_avg = ((top * 2.0 + (zp - top) * math.sqrt(12.0)) / zp) ** 2
    r1 = rtm_bscan(d, x, DT, frequency_hz=F, depth_m=0.6, eps_r=eps_avg, t0_s=T0)
    assert width(r1) > 1.3 * width(r), (width(r1), width(r))


def width(r):
    """Lateral width (m) of the focus at half its height."""
    env = np.abs(hilbert(r.image, axis=1))
    i, k = np.unravel_index(int(np.argmax(env)), env.shape)
    return float(np.count_nonzero(env[:, k] >= 0.5 * env[i, k])) * r.cell_m


def test_eps_column_follows_the_layers():
    z = np.array([0.0, 0.1, 0.2, 0.25, 0.9])
    np.testing.assert_array_equal(eps_column(z, layers=[(0.0, 4.0), (0.2, 9.0), (0.5, 16.0)]),
                                  [4.0, 4.0, 9.0, 9.0, 16.0])
    np.testing.assert_array_equal(eps_column(z, eps_r=5.0), 5.0)
    for bad in ([(0.1, 4.0)], [(0.0, 4.0), (0.0, 9.0)], [(0.0, 0.5)]):
        with pytest.raises(InvalidDataError):
            eps_column(z, layers=bad)


def test_the_sponges_absorb_what_reaches_the_edges():
    """A pulse let go in the middle of a small model: once it has crossed the model several times over, the field
    left is a tiny fraction of what it was (the edges reflect almost nothing back)."""
    n, p = 60, 40
    ey = np.zeros((n + 2 * p, n + 2 * p), np.float32)
    hx, hz = np.zeros_like(ey), np.zeros_like(ey)
    ce = np.full(ey.shape, 0.95 / math.sqrt(2) / 4.0, np.float32)  # c dt / (eps h), eps 4
    ch = np.float32(0.95 / math.sqrt(2))
    g = _sponge(n, p).astype(np.float32)
    src = ricker((np.arange(200) - 40) / 25.0, 1.0).astype(np.float32)[:, None]  # a pulse of ~25 steps, ~9 cells
    _run(ey, hx, hz, ce, ch, g, g, src, p + n // 2, p + n // 2)
    peak = float(np.abs(ey).max())
    _run(ey, hx, hz, ce, ch, g, g, np.zeros((1500, 1), np.float32), p + n // 2, p + n // 2)
    assert float(np.abs(ey[p:p + n, p:p + n]).max()) < 0.01 * peak
    # without the sponges the energy would stay: the test can tell
    ey2 = np.zeros_like(ey)
    hx2, hz2 = np.zeros_like(ey), np.zeros_like(ey)
    ones = np.ones_like(g)
    _run(ey2, hx2, hz2, ce, ch, ones, ones, src, p + n // 2, p + n // 2)
    _run(ey2, hx2, hz2, ce, ch, ones, ones, np.zeros((1500, 1), np.float32), p + n // 2, p + n // 2)
    assert float(np.abs(ey2[p:p + n, p:p + n]).max()) > 0.05 * peak


@pytest.mark.parametrize("change, words", [
    ({"data": np.zeros((1, 50))}, "n_traces >= 2"),
    ({"x_m": np.arange(5.0)}, "x_m has 5 positions but the data have 10 traces"),
    ({"x_m": np.r_[0.0, 0.1, 0.05, np.arange(3, 10) * 0.1]}, "x_m must increase strictly"),
    ({"data": np.full((10, 50), np.nan)}, "NaN"),
    ({"dt_s": 0.0}, "dt_s must be a positive number"),
    ({"frequency_hz": float("nan")}, "frequency_hz must be a positive number"),
    ({"depth_m": -1.0}, "depth_m must be a positive number"),
    ({"eps_r": 0.5}, "eps_r must be >= 1"),
    ({"eps_r": None}, "give eps_r or layers"),
    ({"cell_m": 0.0}, "cell_m must be a positive number"),
    ({"pad_cells": 3}, "pad_cells must be a whole number >= 10"),
    ({"t0_s": 1.0}, "time zero"),
    ({"cell_m": 1e-5}, "give a coarser cell_m"),
])
def test_bad_arguments_are_named(change, words):
    kw = {"data": np.zeros((10, 50)), "x_m": np.arange(10) * 0.02, "dt_s": 0.1e-9, "frequency_hz": 500e6,
          "depth_m": 0.5, "eps_r": 6.0}
    kw.update(change)
    with pytest.raises(InvalidDataError, match=words):
        rtm_bscan(kw.pop("data"), kw.pop("x_m"), kw.pop("dt_s"), **kw)


def test_a_small_model_steps_on_one_thread_and_the_same_image_as_on_several(monkeypatch):
    """Under ``SERIAL_CELLS`` cells the FDTD steps run on one thread (RTMResult.threads), numba's thread count is
    given back afterwards, and the image is the one the parallel steps make (each cell is its own sum: equal to
    the bit)."""
    import numba

    import gpr3d.migration.rtm as rtm

    eps = 6.0
    v = C0 / math.sqrt(eps)
    x = np.arange(0.0, 0.6, 0.01)
    data = bscan(2 * np.hypot(x - 0.3, 0.2) / v)
    had = numba.get_num_threads()
    small = rtm_bscan(data, x, DT, frequency_hz=F, depth_m=0.4, eps_r=eps, t0_s=T0)
    nx, nz = small.image.shape[0] + 80, small.image.shape[1] + 81  # (the sponges: 40 cells a side, the row above)
    assert nx * nz < rtm.SERIAL_CELLS and small.threads == 1
    assert numba.get_num_threads() == had
    monkeypatch.setattr(rtm, "SERIAL_CELLS", 0)  # every model counts as large: numba's threads
    large = rtm_bscan(data, x, DT, frequency_hz=F, depth_m=0.4, eps_r=eps, t0_s=T0)
    assert large.threads == had and numba.get_num_threads() == had
    np.testing.assert_array_equal(small.image, large.image)
    assert np.abs(small.image).max() > 0  # (a field that reached the image, not two empty ones)
