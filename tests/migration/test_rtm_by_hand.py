"""RTM's set-up by hand: the grid, the time step, the sponges and the source traces resampled onto the cells and
steps, captured where they enter the FDTD kernel (replaced here), against values worked out in the test."""

import math
import time

import numpy as np
import pytest

import gpr3d.migration.rtm as rtm
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0


@pytest.fixture
def captured(monkeypatch):
    got = {}

    def run(ey, hx, hz, ce, ch, gx, gz, src, src_i0, ks):
        got.update(ey=ey.copy(), shapes=(ey.shape, hx.shape, hz.shape), dtypes=(ey.dtype, hx.dtype, hz.dtype),
                   ce=ce.copy(), ce_dtype=ce.dtype, ch=ch, gx=gx.copy(), gz=gz.copy(), src=src.copy(),
                   src_i0=src_i0, ks=ks)
        ey[:] = np.arange(ey.size, dtype=np.float32).reshape(ey.shape)  # a field to cut the image from

    monkeypatch.setattr(rtm, "_run", run)
    return got


def _sponge(n, pad):
    a = 0.29 / pad
    g = np.ones(n + 2 * pad)
    for i in range(pad):  # i cells from the outer edge: pad - i cells into the pad
        g[i] = g[-1 - i] = math.exp(-((a * (pad - i)) ** 2))
    return g


def test_the_sponge_by_hand():
    np.testing.assert_allclose(rtm._sponge(5, 12), _sponge(5, 12), rtol=1e-15, atol=0)
    assert rtm._sponge(5, 12)[0] == pytest.approx(math.exp(-0.29**2)) and rtm._sponge(5, 12)[12] == 1.0


def test_the_grid_steps_sponges_and_source_by_hand(captured):
    rng = np.random.default_rng(0)
    n_tr, ns, dt_s, f, eps = 6, 40, 1e-10, 1e9, 4.0
    x = np.array([0.0, 0.01, 0.03, 0.04, 0.06, 0.075])  # uneven steps
    data = rng.normal(size=(n_tr, ns))
    res = rtm.rtm_bscan(data, x, dt_s, frequency_hz=f, depth_m=0.05, eps_r=eps, t0_s=0.35e-9, pad_cells=12)
    h = C0 / (2 * f * math.sqrt(4 * eps)) / 10  # a tenth of the shortest wavelength (twice f) at half speed
    nxc, nzc = int(0.075 // h) + 1, int(0.05 // h) + 1
    nx, nz = nxc + 24, nzc + 25
    dt = 0.95 * h / (C0 / math.sqrt(4 * eps) * math.sqrt(2))
    t_end = (ns - 1) * dt_s - 0.35e-9
    steps = math.ceil(t_end / dt)
    assert res.cell_m == pytest.approx(h, rel=1e-15) and res.steps == steps and res.wall_s > 0
    assert captured["shapes"] == ((nx, nz),) * 3 and captured["dtypes"] == (np.float32,) * 3
    assert not captured["ey"].any() and captured["ks"] == 12 and captured["src_i0"] == 12
    assert captured["ch"] == pytest.approx(C0 * dt / h, rel=1e-6) and captured["ce_dtype"] == np.float32
    np.testing.assert_allclose(captured["ce"], np.full((nx, nz), C0 * dt / h / (4 * eps)), rtol=1e-6)
    np.testing.assert_allclose(captured["gx"], _sponge(nxc, 12), rtol=1e-6)
    np.testing.assert_allclose(captured["gz"], _sponge(nzc + 1, 12)[:nz], rtol=1e-6)
    # the source: each step n at time t_end - n dt after time zero, linear in time, then linear along x
    xs = x[0] + h * np.arange(nxc)
    want = np.empty((steps, nxc))
    for n in range(steps):
        u = (t_end - n * dt + 0.35e-9) / dt_s
        per_trace = np.array([np.interp(u, np.arange(ns), d) for d in data])
        want[n] = np.interp(xs, x, per_trace)
    np.testing.assert_allclose(captured["src"], want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(res.x_m, xs, rtol=0, atol=1e-15)
    np.testing.assert_allclose(res.depth_m, h * np.arange(nzc), rtol=0, atol=1e-15)
    field = np.arange(nx * nz, dtype=np.float32).reshape(nx, nz)
    np.testing.assert_array_equal(res.image, field[12:12 + nxc, 12:12 + nzc])


def test_layers_set_the_cell_the_step_and_the_column_and_a_given_cell_wins(captured):
    data = np.random.default_rng(1).normal(size=(4, 30))
    x = np.array([0.0, 0.02, 0.04, 0.06])
    layers = [(0.0, 4.0), (0.03, 9.0)]
    res = rtm.rtm_bscan(data, x, 1e-10, frequency_hz=1e9, depth_m=0.05, layers=layers, pad_cells=10)
    h = C0 / (2e9 * math.sqrt(36.0)) / 10  # the slowest layer sets the cell
    dt = 0.95 * h / (C0 / math.sqrt(16.0) * math.sqrt(2))  # the fastest the step
    assert res.cell_m == pytest.approx(h, rel=1e-15) and res.steps == math.ceil(29e-10 / dt)
    rows = (np.arange(captured["ce"].shape[1]) - 10) * h
    eps_rows = np.where(np.maximum(rows, 0) >= 0.03, 36.0, 16.0)
    np.testing.assert_allclose(captured["ce"][0], C0 * dt / h / eps_rows, rtol=1e-6)
    res = rtm.rtm_bscan(data, x, 1e-10, frequency_hz=1e9, depth_m=0.05, eps_r=4.0, cell_m=0.004, pad_cells=10)
    assert res.cell_m == 0.004 and res.x_m.size == 16 and res.depth_m.size == 13


def test_eps_column_by_hand():
    d = np.array([0.0, 0.1, 0.2999, 0.3, 0.5, 2.0])
    np.testing.assert_array_equal(rtm.eps_column(d, 5), np.full(6, 5.0))
    np.testing.assert_array_equal(rtm.eps_column(d, layers=[(0, 4.0), (0.3, 9.0), (1.0, 16.0)]),
                                  [4, 4, 4, 9, 9, 16])
    np.testing.assert_array_equal(rtm.eps_column([0.2], layers=[(0, 1.0)]), [1.0])  # eps 1 is allowed (air)
    assert rtm.eps_column(0.5, 3).shape == ()


@pytest.mark.parametrize("kw, message", [
    (dict(), "give eps_r or layers for the migration velocity"),
    (dict(layers=[]), "layers must start at depth 0 and deepen"),
    (dict(layers=[(0.1, 4.0)]), "layers must start at depth 0 and deepen"),
    (dict(layers=[(0.0, 4.0), (0.2, 5.0), (0.2, 6.0)]), "layers must start at depth 0 and deepen"),
    (dict(layers=[(0.0, 4.0), (0.2, 0.5)]), "layer eps_r must be finite and >= 1, got [4.0, 0.5]"),
    (dict(layers=[(0.0, float("nan"))]), "layer eps_r must be finite and >= 1, got [nan]"),
])
def test_eps_column_messages_in_full(kw, message):
    with pytest.raises(InvalidDataError) as err:
        rtm.eps_column(np.array([0.1]), **kw)
    assert str(err.value) == message


@pytest.mark.parametrize("args, kw, message", [
    ((np.zeros((1, 10)), [0.0]), {}, "data must be a B-scan (n_traces >= 2, n_samples >= 2), got shape (1, 10)"),
    ((np.zeros((3, 1)), [0.0, 0.1, 0.2]), {}, "data must be a B-scan (n_traces >= 2, n_samples >= 2), got shape (3, 1)"),
    ((np.zeros(10), [0.0]), {}, "data must be a B-scan (n_traces >= 2, n_samples >= 2), got shape (10,)"),
    ((np.zeros((3, 10)), [0.0, 0.1]), {}, "x_m has 2 positions but the data have 3 traces"),
    ((np.full((2, 10), np.nan), [0.0, 0.1]), {}, "the data hold NaN or infinite samples"),
    ((np.zeros((2, 10)), [0.1, 0.1]), {}, "x_m must increase strictly along the line (a straight B-scan, traces in "
                                          "order)"),
    ((np.zeros((2, 10)), [0.0, 0.1]), dict(pad_cells=9), "pad_cells must be a whole number >= 10, got 9"),
    ((np.zeros((2, 10)), [0.0, 0.1]), dict(pad_cells=10.0), "pad_cells must be a whole number >= 10, got 10.0"),
    ((np.zeros((2, 10)), [0.0, 0.1]), dict(eps_r=0.5), "eps_r must be >= 1, got [0.5, 0.5]"),
    ((np.zeros((2, 10)), [0.0, 0.1]), dict(t0_s=9e-10), "time zero (9e-10 s) must lie inside the record (10 samples "
                                                         "of 1e-10 s)"),
    ((np.zeros((2, 10)), [0.0, 0.1]), dict(cell_m=0.0), "cell_m must be a positive number of metres, got 0.0"),
])
def test_rtm_messages_in_full(args, kw, message):
    kw = {"eps_r": 4.0, **kw}
    with pytest.raises(InvalidDataError) as err:
        rtm.rtm_bscan(*args, 1e-10, frequency_hz=1e9, depth_m=0.05, **kw)
    assert str(err.value) == message


def test_the_smallest_record_and_time_zero_one_step_short_of_its_end(captured):
    res = rtm.rtm_bscan(np.ones((2, 2)), [0.0, 0.01], 1e-10, frequency_hz=1e9, depth_m=0.02, eps_r=4.0, pad_cells=10,
                        t0_s=0.99e-10)
    assert res.steps == 1 and captured["src"].shape[0] == 1
    np.testing.assert_allclose(captured["src"], 1.0, rtol=1e-6)


def test_too_much_work_is_refused(monkeypatch, captured):
    monkeypatch.setattr(rtm, "MAX_WORK", 1000.0)
    with pytest.raises(InvalidDataError, match=r"^the RTM model would be \d+ x \d+ cells x \d+ steps \(cell [0-9.]+ "
                                               r"mm\): give a coarser cell_m or a shallower depth_m$"):
        rtm.rtm_bscan(np.zeros((2, 10)), [0.0, 0.1], 1e-10, frequency_hz=1e9, depth_m=0.05, eps_r=4.0)


def test_the_steps_run_on_one_thread_below_serial_cells_and_the_count_is_given_back(monkeypatch, captured):
    """numba's thread calls replaced by a record (whatever threads this machine or the mutation run has): a model
    of fewer than SERIAL_CELLS cells steps on one thread, one of exactly that many on all; the count set back."""
    calls = []
    monkeypatch.setattr(rtm.numba, "get_num_threads", lambda: 4)
    monkeypatch.setattr(rtm.numba, "set_num_threads", lambda n: calls.append((n, "ey" in captured)))
    data = np.random.default_rng(2).normal(size=(4, 30))
    kw = dict(frequency_hz=2e9, depth_m=0.05, eps_r=6.0, pad_cells=12)
    x = np.linspace(0.0, 0.075, 4)
    t0 = time.perf_counter()
    res = rtm.rtm_bscan(data, x, 25e-12, **kw)
    elapsed = time.perf_counter() - t0
    assert 0 < res.wall_s <= elapsed  # (its own wall time: inside the call's)
    nx, nz = captured["shapes"][0]
    assert nx * nz > 1000 and res.threads == 1
    assert calls == [(1, False), (4, True)]  # one thread set before the kernel ran, the count set back after it
    calls.clear()
    captured.clear()
    monkeypatch.setattr(rtm, "SERIAL_CELLS", nx * nz)  # the same model, now exactly at the limit: all threads
    assert rtm.rtm_bscan(data, x, 25e-12, **kw).threads == 4 and calls == [(4, False), (4, True)]
    monkeypatch.setattr(rtm, "SERIAL_CELLS", nx * nz + 1)
    assert rtm.rtm_bscan(data, x, 25e-12, **kw).threads == 1
