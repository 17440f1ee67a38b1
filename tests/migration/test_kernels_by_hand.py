"""The migration kernels' Python side by hand: the build probe, the cache of built kernels, the trace binning of the
tiled adjoint, and the read-path override. Every test starts from an empty cache, so that building is exercised
(and not a kernel some earlier test built)."""

import math

import numpy as np
import pytest

from gpr3d.migration import _kernels
from gpr3d.migration._kernels import GATHER, LOADS, W, f32


@pytest.fixture(autouse=True)
def fresh_cache(monkeypatch):
    monkeypatch.setattr(_kernels, "_CACHE", {})


def _consistent_problem(args):
    """The probe's arguments as the kernels take them: one float32 problem whose shapes agree (None if so, else
    what is wrong). Positional: data, tx, rx, gap, x, y, depth, slow, t0, inv_dt, umax, tan_ap, rmax2, mode, image,
    and for the tiled kernel order, bin_start, bx0, by0, bsize, nbx, nby, mid, reach, fold_img."""
    data, tx, rx, gap, x, y, depth, slow, t0, inv_dt, umax, tan_ap, rmax2, mode, image = args[:15]
    arrays = dict(data=data, tx=tx, rx=rx, gap=gap, x=x, y=y, depth=depth, slow=slow, image=image)
    for name, a in arrays.items():
        if not (isinstance(a, np.ndarray) and a.dtype == np.float32):
            return f"{name} is not a float32 array"
    for name, s in dict(t0=t0, inv_dt=inv_dt, umax=umax, tan_ap=tan_ap, rmax2=rmax2).items():
        if not isinstance(s, np.float32):
            return f"{name} is not a float32 scalar"
    n = data.shape[0]
    if data.ndim != 2 or tx.shape != (n, 3) or rx.shape != (n, 3) or gap.shape != (n,):
        return "the traces' arrays disagree"
    if depth.ndim != 1 or depth.size % W or slow.shape != depth.shape:
        return "depth and slowness must be whole SIMD blocks"
    if image.shape[:2] != (x.size, y.size) or not 0 < image.shape[2] <= depth.size:
        return "the image does not match the grid"
    if not isinstance(mode, int):
        return "mode is not an int"
    if not rmax2 > 0:
        return "rmax2 (the aperture's squared radius) is not positive: every column would be cut off"
    if len(args) == 15:
        return None
    order, start, bx0, by0, bsize, nbx, nby, mid, reach, krange, fold = args[15:]
    if order.dtype != np.int64 or start.dtype != np.int64 or order.ndim != 1:
        return "the bins are not int64"
    if start.shape != (nbx * nby + 1,) or start[-1] != order.size or np.any(np.diff(start) < 0):
        return "the bins' starts do not match"
    if mid.dtype != np.float32 or mid.shape != (n, 2) or fold.dtype != np.float32:
        return "midpoints or fold"
    if fold.shape not in (image.shape, (1, 1, 1)):
        return "the fold image does not match"
    if krange.dtype != np.int32 or krange.shape != image.shape[:2] + (2,) or not krange.flags.c_contiguous:
        return "the depth ranges are not int32 (nx, ny, 2)"
    if np.any(krange[..., 1] > image.shape[2]) or not np.any(krange[..., 1] > krange[..., 0]):
        return "the depth ranges sum nothing or reach past the image"
    if not all(isinstance(s, np.float32) for s in (bx0, by0, bsize, reach)):
        return "a bin scalar is not float32"
    return None


@pytest.mark.parametrize("extra", [False, True])
def test_the_probe_runs_one_consistent_float32_problem_in_every_weight_mode(extra):
    calls = []

    def fake(*args):
        calls.append(args)
        assert _consistent_problem(args) is None, _consistent_problem(args)

    tiled_extra = (np.zeros(0, np.int64), np.zeros(2, np.int64), f32(0), f32(0), f32(1), 1, 1,
                   np.zeros((1, 2), np.float32), f32(1), np.array([[[0, 2]]], np.int32),
                   np.zeros((1, 1, 2), np.float32))
    assert _kernels._probe(fake, *(tiled_extra if extra else ())) is fake
    assert [c[13] for c in calls] == [0, 1, 2, 3]
    assert all(len(c) == (26 if extra else 15) for c in calls)


def test_a_kernel_that_fails_to_build_or_run_is_none():
    def broken(*args):
        raise TypeError("no such intrinsic here")

    assert _kernels._probe(broken) is None


def test_the_kernels_build_here_once_per_path_and_fold(monkeypatch):
    built = []
    real = _kernels._probe

    def checked(fn):
        def run(*args):
            assert _consistent_problem(args) is None, _consistent_problem(args)
            return fn(*args)
        return run

    # every probe builds one consistent float32 problem (a wrong one makes the probe, and so the kernel, None)
    monkeypatch.setattr(_kernels, "_probe",
                        lambda fn, *extra: built.append(len(extra)) or (fn if real(checked(fn), *extra) else None))
    g, lo = _kernels.simd_adjoint(GATHER), _kernels.simd_adjoint(LOADS)
    assert g is not None and lo is not None and g is not lo
    assert _kernels.simd_adjoint(GATHER) is g and _kernels.simd_adjoint() is g  # built once, GATHER by default
    tiles = {(p, f): _kernels.tiled_adjoint(p, f) for p in (0, GATHER, LOADS) for f in (False, True)}
    assert all(t is not None for t in tiles.values()) and len({id(t) for t in tiles.values()}) == 6
    assert _kernels.tiled_adjoint(0) is tiles[(0, False)]  # no fold unless asked
    assert built == [0, 0] + [11] * 6


def test_a_kernel_whose_probe_fails_is_none(monkeypatch):
    monkeypatch.setattr(_kernels, "_probe", lambda fn, *extra: None)
    assert _kernels.simd_adjoint(GATHER) is None and _kernels.tiled_adjoint(0) is None
    assert _kernels.tiled_adjoint(LOADS, True) is None


def _problem(rng, n=40, nd=13):
    """A small random problem in the kernels' arguments (depth padded to whole SIMD blocks for the SIMD kernels)."""
    from gpr3d.core.grid import Grid3D
    from gpr3d.migration.operator import BackProjection, antenna_positions

    pos = np.c_[rng.uniform(0, 0.6, n), rng.uniform(0, 0.6, n), np.zeros(n)]
    tx, rx = antenna_positions(pos, headings_rad=rng.uniform(-3, 3, n), offset_m=0.1)
    grid = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.02, 9, 10, nd)
    op = BackProjection(grid, tx, rx, dt_s=0.1e-9, n_samples=120, eps_r=6.0, aperture_deg=30, engine="numba")
    data = np.zeros((n, 122), np.float32)
    data[:, :120] = rng.standard_normal((n, 120))
    return op, data


@pytest.mark.parametrize("path", [GATHER, LOADS])
def test_each_built_kernel_runs_its_own_path_and_sums_what_the_scalar_one_does(path):
    rng = np.random.default_rng(5)
    op, data = _problem(rng)
    args = list(op._kernel_args(op.grid.x, op.grid.y))
    want = np.zeros(op.grid.shape, np.float32)
    _kernels.kernels()[0](data, *args, want)
    extra = -op.grid.nd % W
    sargs = list(args)
    sargs[5] = np.r_[np.full(extra, args[5][0]), args[5]].astype(np.float32)
    sargs[6] = np.r_[np.full(extra, args[6][0]), args[6]].astype(np.float32)
    got = np.zeros(op.grid.shape, np.float32)
    _kernels.simd_adjoint(path)(data, *sargs, got)
    peak = np.abs(want).max()
    assert peak > 0
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * peak)
    mid = (0.5 * (op.tx[:, :2] + op.rx[:, :2])).astype(np.float32)
    bsize = max(op.reach_m / 2, _kernels.TILE * 0.05)
    order, start, bx0, by0, nbx, nby = _kernels.bin_traces(mid, bsize)
    every = np.zeros(op.grid.shape[:2] + (2,), np.int32)
    every[..., 1] = op.grid.nd
    for p, a in ((0, args), (path, sargs)):
        for fold in (False, True):
            img = np.zeros(op.grid.shape, np.float32)
            fimg = np.zeros(op.grid.shape if fold else (1, 1, 1), np.float32)
            _kernels.tiled_adjoint(p, fold)(data, *a, img, order, start, f32(bx0), f32(by0), f32(bsize), nbx, nby,
                                            mid, f32(op.reach_m), every, fimg)
            np.testing.assert_allclose(img, want, rtol=0, atol=1e-5 * peak)
            assert (fimg.max() > 1.0) == fold  # the fold of a trace of ones counts the traces, when asked


def test_traces_binned_by_their_midpoints_by_hand():
    # side 0.5: origin (0.5, -0.5), 3 x 2 bins; bin index (mid - origin) // side, numbered i * nby + j
    mid = np.array([[0.7, -0.2], [1.6, 0.3], [0.9, 0.4], [0.74, -0.1]])
    order, start, bx0, by0, nbx, nby = _kernels.bin_traces(mid, 0.5)
    assert (bx0, by0, nbx, nby) == (0.5, -0.5, 3, 2)
    # bins: 0 (0, 0), 5 (2, 1), 1 (0, 1), 0
    assert order.tolist() == [0, 3, 2, 1] and order.dtype == np.int64
    assert start.tolist() == [0, 2, 3, 3, 3, 3, 4] and start.dtype == np.int64


def test_bins_use_floor_division_on_every_edge():
    # side 0.1 from 0: 1.3 // 0.1 is 12 (1.3 / 0.1 rounds to 13): 13 bins along x; 0.9 // 0.1 is 8 (/: 9)
    mid = np.array([[0.0, 0.0], [1.3, 0.0], [0.9, 0.0], [0.35, 0.0]])
    order, start, bx0, by0, nbx, nby = _kernels.bin_traces(mid, 0.1)
    assert (bx0, by0, nbx, nby) == (0.0, 0.0, 13, 1)
    assert start.tolist() == [0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 4]  # bins 0, 3, 8, 12
    assert order.tolist() == [0, 3, 2, 1]
    # the same along y (x and y swapped)
    order, start, bx0, by0, nbx, nby = _kernels.bin_traces(mid[:, ::-1].copy(), 0.1)
    assert (bx0, by0, nbx, nby) == (0.0, 0.0, 1, 13)
    assert start.tolist() == [0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 4] and order.tolist() == [0, 3, 2, 1]
    # an origin below zero: -0.3 / 0.1 is -2.9999999999999996, floored to -3; y then spans 0.55 // 0.1 + 1 bins
    o, s, bx, by, nx, ny = _kernels.bin_traces(np.array([[0.05, -0.3], [0.05, 0.25]]), 0.1)
    assert (bx, by, nx, ny) == (0.0, -3 * 0.1, 1, 6)
    assert s.tolist() == [0, 1, 1, 1, 1, 1, 2] and o.tolist() == [0, 1]


def test_many_traces_in_few_bins_keep_their_order_within_each_bin():
    rng = np.random.default_rng(3)
    mid = np.c_[rng.choice([0.1, 0.6, 1.1], 300), rng.choice([0.2, 0.7], 300)]
    order, start, bx0, by0, nbx, nby = _kernels.bin_traces(mid, 0.5)
    assert (nbx, nby) == (3, 2)
    b = ((mid[:, 0] // 0.5) * 2 + mid[:, 1] // 0.5).astype(int)
    want = [i for k in range(6) for i in range(300) if b[i] == k]
    assert order.tolist() == want
    assert start.tolist() == [0] + np.cumsum(np.bincount(b, minlength=6)).tolist()


def test_the_read_path_override_beats_the_cpu(monkeypatch):
    import llvmlite.binding as llb

    monkeypatch.setattr(llb, "get_host_cpu_name", lambda: "sapphirerapids")
    monkeypatch.setenv("GPR3D_GATHER", "0")
    assert _kernels.read_path() == LOADS  # scalar loads, though the CPU gathers fast
    monkeypatch.setattr(llb, "get_host_cpu_name", lambda: "znver4")
    monkeypatch.setenv("GPR3D_GATHER", "1")
    assert _kernels.read_path() == GATHER
    monkeypatch.setenv("GPR3D_GATHER", "auto")
    assert _kernels.read_path() == LOADS


def test_building_the_tiled_kernel_first_waits_for_a_background_warm_up_of_it(monkeypatch):
    """(gpr3d.core.warmup) the tiled kernel is the group the background warm-up compiles: building it waits for
    that group, once; the untiled ones wait for nothing."""
    import gpr3d.core.warmup as warmup

    waited = []
    monkeypatch.setattr(warmup, "wait", lambda group: waited.append(group) or 0.0)
    monkeypatch.setattr(_kernels, "_probe", lambda fn, *extra: fn)
    _kernels.tiled_adjoint(0, False)
    _kernels.tiled_adjoint(0, False)  # built: no second wait
    assert waited == ["tiled"]
    _kernels.simd_adjoint(LOADS)
    _kernels.kernels()
    assert waited == ["tiled"]


def test_a_preload_builds_the_tiled_kernel_once_while_another_thread_asks_for_it(monkeypatch):
    """preload_tiled loads the tiled kernel in a thread of its own; a command that asks for it meanwhile waits for
    that thread and gets the same kernel: it is probed once (two threads probing it at once abort numba's workqueue
    threading layer)."""
    import threading
    import time

    import gpr3d.core.warmup as warmup

    monkeypatch.setattr(warmup, "wait", lambda group: 0.0)
    monkeypatch.setattr(warmup, "done", lambda: {"tiled"})  # the warm-up has compiled it: it is preloaded
    probed, started = [], threading.Event()

    def slow_probe(fn, *extra):
        started.set()
        time.sleep(0.3)  # a load from numba's cache takes about this long
        probed.append(threading.current_thread().name)
        return fn

    monkeypatch.setattr(_kernels, "_probe", slow_probe)
    monkeypatch.setenv("GPR3D_GATHER", "0")  # this CPU's read path, whichever it is: scalar loads
    t = _kernels.preload_tiled(GATHER)  # the path given wins
    assert isinstance(t, threading.Thread) and t.daemon
    assert started.wait(5.0)  # the preload is inside its probe: the main thread asks now
    k = _kernels.tiled_adjoint(GATHER, True)
    t.join(5.0)
    assert probed == ["gpr3d-preload-tiled"] and k is not None
    assert _kernels.tiled_adjoint(GATHER, True) is k and list(_kernels._CACHE) == [("tiled", GATHER, True)]
    # with no path given, the read path of this CPU (set above: loads); no fold asked: the one with the fold
    t = _kernels.preload_tiled()
    t.join(5.0)
    assert ("tiled", LOADS, True) in _kernels._CACHE and len(probed) == 2


def test_only_a_kernel_the_warm_up_compiled_is_preloaded(monkeypatch):
    import gpr3d.core.warmup as warmup
    from gpr3d.migration import preload_tiled

    probed = []
    monkeypatch.setattr(_kernels, "_probe", lambda fn, *extra: probed.append(1) or fn)
    monkeypatch.setattr(warmup, "done", lambda: set())  # not compiled yet: the command builds it, timed, itself
    assert preload_tiled(LOADS) is None and probed == [] and _kernels._CACHE == {}
    monkeypatch.setattr(warmup, "done", lambda: {"tiled"})
    preload_tiled(LOADS).join(5.0)
    assert probed == [1] and ("tiled", LOADS, True) in _kernels._CACHE
