"""The PyTorch back projection (the GPU path) is the operator of the numba kernels and the numpy reference: the
same images and data to float32 rounding, for every weight, an aperture, heights, layers, a window of columns and
any batch size; run here on the CPU (``"torch"``), as the tests never need a GPU."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.migration.operator import effective_slowness
from tests.migration.test_operator import GRID, RNG, clear_of_the_radius, make

torch = pytest.importorskip("torch")


@pytest.mark.parametrize("kw", [{}, {"aperture_deg": 40, "obliquity": True}, {"spreading": True},
                                {"aperture_deg": 30, "obliquity": True, "spreading": True},
                                {"heights": True, "aperture_deg": 40}, {"heights": True, "t0_s": -2e-9},
                                {"aperture_m": 0.3, "obliquity": True}, {"aperture_deg": 40, "aperture_m": 0.25}])
def test_torch_matches_the_numpy_reference_and_numba(kw):
    ref, nb, tc = make("numpy", **kw), make("numba", **kw), make("torch", **kw)
    assert clear_of_the_radius(ref)
    d = RNG.standard_normal((25, 200)).astype(np.float32)
    ia, it = ref.adjoint(d), tc.adjoint(d)
    assert it.dtype == np.float32 and it.shape == GRID.shape
    np.testing.assert_allclose(it, ia, atol=1e-4 * np.abs(ia).max())
    np.testing.assert_allclose(it, nb.adjoint(d), atol=1e-4 * np.abs(ia).max())
    m = RNG.standard_normal(GRID.shape).astype(np.float32)
    fa, ft = ref.forward(m), tc.forward(m)
    assert ft.dtype == np.float32 and ft.shape == (25, 200)
    np.testing.assert_allclose(ft, fa, atol=1e-4 * np.abs(fa).max())
    # an exact adjoint pair (float32 sums: against the vectors' sizes)
    lhs, rhs = float(np.sum(ft.astype(np.float64) * d)), float(np.sum(m * it.astype(np.float64)))
    assert abs(lhs - rhs) <= 1e-6 * np.linalg.norm(ft) * np.linalg.norm(d)


def test_layers_a_window_the_fold_and_small_batches(monkeypatch):
    from gpr3d.migration import _torch

    ref, tc = make("numpy", aperture_deg=40), make("torch", aperture_deg=40)
    for op in (ref, tc):
        op.slow = effective_slowness(GRID.depth, layers=[(0.0, 4.0), (0.2, 9.0)])
    d = RNG.standard_normal((25, 200)).astype(np.float32)
    whole = ref.adjoint(d)
    monkeypatch.setattr(_torch, "PAIRS_PER_BATCH", 3 * 21 * 21 * 25)  # a few traces a batch, windows of columns
    assert len(_torch._plan(tc, tc.x, tc.y)) > 5
    np.testing.assert_allclose(tc.adjoint(d), whole, atol=1e-4 * np.abs(whole).max())
    part = tc.adjoint(d, window=(3, 11, 5, 21))
    np.testing.assert_allclose(part, whole[3:11, 5:21], atol=1e-4 * np.abs(whole).max())
    img, fold = tc.adjoint(d, with_fold=True)
    ones = ref.adjoint(np.ones_like(d))
    np.testing.assert_allclose(fold, ones, atol=1e-4 * ones.max())
    m = RNG.standard_normal(GRID.shape).astype(np.float32)
    np.testing.assert_allclose(tc.forward(m), ref.forward(m), atol=1e-4 * np.abs(ref.forward(m)).max())


@pytest.mark.parametrize("engine, msg", [
    ("torch:tpu9", "is not a torch device"), ("numba:cuda", "engine must be one of"),
    ("torch:meta", "only cpu and cuda devices")])
def test_a_device_that_is_not_there_is_one_line(engine, msg):
    with pytest.raises(InvalidDataError, match=msg):
        make(engine)


def test_cuda_where_there_is_none_and_an_air_gap_are_refused():
    if torch.cuda.is_available():  # (on a GPU machine the CUDA engine is the same operator)
        ref, gpu = make("numpy"), make("torch:cuda")
        d = RNG.standard_normal((25, 200)).astype(np.float32)
        np.testing.assert_allclose(gpu.adjoint(d), ref.adjoint(d), atol=1e-4 * np.abs(ref.adjoint(d)).max())
    else:
        with pytest.raises(InvalidDataError, match="no CUDA device is available here"):
            make("torch:cuda")
    with pytest.raises(InvalidDataError, match=r"^the torch engine has no air gap \(rays refracted at the surface\): "
                                               r"use engine 'numba' for an antenna above the ground$"):
        make("torch", air=True)
    assert make("torch").engine == "torch" and make("torch").torch_device == "cpu"


def test_a_reconstruction_with_the_torch_engine_is_the_numba_one():
    from gpr3d import Survey
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct
    from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
    from gpr3d.simulation.paths import random_walk

    walk = random_walk(300, area=((0, 0.5), (0, 0.5)), step_m=0.01, seed=2)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.05, 0.25, -0.2), (0.45, 0.25, -0.2), 0.02)])
    data = forward_model(scene, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.05, frequency_hz=1e9,
                         n_samples=128, time_window_s=8e-9, air_wave=1.0, ground_wave=0.5)
    s = Survey(data=data, dt_s=8e-9 / 128, offset_m=0.05, frequency_hz=1e9, eps_r=6.0,
               positions_xyz=walk.positions_xyz, orientations_quat_wxyz=walk.orientations_quat_wxyz)
    a = reconstruct(s, ReconstructConfig(eps_r=6.0, spacing_m=0.02, max_depth_m=0.4), log=lambda m: None)
    b = reconstruct(s, ReconstructConfig(eps_r=6.0, spacing_m=0.02, max_depth_m=0.4, engine="torch"),
                    log=lambda m: None)
    np.testing.assert_allclose(b.envelope, a.envelope, atol=1e-4 * np.abs(a.envelope).max())
    assert [t.kind for t in b.targets] == [t.kind for t in a.targets] and a.targets
    for ta, tb in zip(a.targets, b.targets):
        np.testing.assert_allclose(tb.points_xyz, ta.points_xyz, atol=1e-3)


def test_the_engine_names_and_the_command_line_s_device():
    from gpr3d.cli.main import main
    from gpr3d.migration.operator import check_engine

    assert check_engine("numba") == ("numba", None) and check_engine("torch") == ("torch", "cpu")
    assert check_engine("torch:cpu") == ("torch", "cpu")
    with pytest.raises(InvalidDataError, match="engine must be one of 'numba', 'numpy', 'torch'"):
        check_engine("cupy")
    import contextlib
    import io

    if not torch.cuda.is_available():  # --device cuda on a machine without one: one line before any work
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            rc = main(["reconstruct", "x.h5", "--eps-r", "6", "--device", "cuda", "--out", "/nonexistent/r"])
        assert rc == 1 and "no CUDA device is available here" in err.getvalue(), err.getvalue()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["reconstruct", "x.h5", "--eps-r", "6", "--device", "cuda:0", "--engine", "numba", "--out", "r"])
    assert rc == 1 and "--device cuda:0 migrates with the torch engine: leave out --engine numba" in err.getvalue()


def test_the_batches_take_every_trace_once_with_the_columns_their_cones_reach(monkeypatch):
    from gpr3d.core.grid import Grid3D
    from gpr3d.migration import _torch
    from gpr3d.migration.operator import BackProjection, antenna_positions

    rng = np.random.default_rng(5)
    pos = np.c_[rng.uniform(0, 3, 60), rng.uniform(0, 3, 60), np.zeros(60)]
    tx, rx = antenna_positions(pos, headings_rad=rng.uniform(-3, 3, 60), offset_m=0.1)
    grid = Grid3D(0, 0, 0.04, 0.05, 0.05, 0.02, 61, 61, 12)
    kw = dict(dt_s=0.1e-9, n_samples=120, eps_r=6.0, aperture_deg=30, obliquity=True)
    ref, tc = BackProjection(grid, tx, rx, **kw, engine="numpy"), BackProjection(grid, tx, rx, **kw, engine="torch")
    monkeypatch.setattr(_torch, "PAIRS_PER_BATCH", 40_000)  # batches of cones, some spread out and split
    plan = _torch._plan(tc, tc.x, tc.y)
    assert sorted(np.concatenate([p[0] for p in plan]).tolist()) == list(range(60))
    mid = 0.5 * (tx[:, :2] + rx[:, :2])
    for idx, ix0, ix1, iy0, iy1 in plan:  # every column a cone reaches lies in its batch's window
        for j in idx:
            near_x = np.nonzero(np.abs(grid.x - mid[j, 0]) <= tc.reach_m)[0]
            near_y = np.nonzero(np.abs(grid.y - mid[j, 1]) <= tc.reach_m)[0]
            assert ix0 <= near_x.min() and near_x.max() < ix1 and iy0 <= near_y.min() and near_y.max() < iy1
    d = rng.standard_normal((60, 120)).astype(np.float32)
    ia = ref.adjoint(d)
    np.testing.assert_allclose(tc.adjoint(d), ia, atol=1e-4 * np.abs(ia).max())
    m = rng.standard_normal(grid.shape).astype(np.float32)
    fa = ref.forward(m)
    np.testing.assert_allclose(tc.forward(m), fa, atol=1e-4 * np.abs(fa).max())
