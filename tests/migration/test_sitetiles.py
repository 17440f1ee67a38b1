import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.migration.operator import BackProjection, effective_slowness
from gpr3d.migration.sitetiles import migrate_site, plan_tiles, tile_traces
from tests.migration.test_operator import scattered_antennas

RNG = np.random.default_rng(21)
N = 400
# traces over 2.4 m x 2.4 m, some beyond the grid's edges, a few lifted; a grid of 2.2 m x 1.8 m at 5 cm
TX, RX = scattered_antennas(RNG, N, -0.2, 2.2, 0.04, offset=0.12)
GRID = Grid3D(0.0, 0.0, 0.04, 0.05, 0.05, 0.03, 45, 37, 24)
DATA = RNG.standard_normal((N, 160)).astype(np.float32)


def op(engine="numba", aperture=30.0, **kw):
    return BackProjection(GRID, TX, RX, dt_s=0.1e-9, n_samples=160, t0_s=0.5e-9, eps_r=5.0, aperture_deg=aperture,
                          obliquity=True, spreading=True, engine=engine, **kw)


def test_tiles_cover_every_column_once():
    tiles = plan_tiles(GRID, 0.45)  # 9 columns: rounded to 8
    cover = np.zeros((GRID.nx, GRID.ny), int)
    for t in tiles:
        assert (t.ix1 - t.ix0) <= 8 and (t.iy1 - t.iy0) <= 8
        cover[t.ix0:t.ix1, t.iy0:t.iy1] += 1
    assert (cover == 1).all()
    assert len(tiles) == 6 * 5
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InvalidDataError, match="tile size"):
            plan_tiles(GRID, bad)


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_tiles_in_one_process_give_the_whole_image_bit_for_bit(engine):
    """Tiles of 8 x 8 columns (0.4 m, with a 0.5 m halo: most traces fall out of each tile's reach) migrated from
    their own traces only equal, exactly, the image and fold of one migration over the whole grid."""
    o = op(engine)
    want_img, want_fold = o.adjoint(DATA, with_fold=True)
    got = migrate_site(o, DATA, tile_m=0.4)
    assert got.tiles == 30 and got.resumed == 0
    np.testing.assert_array_equal(got.image, want_img)
    np.testing.assert_array_equal(got.fold, want_fold)
    # the halo did cull: a tile takes well under all the traces, and no tile is empty
    assert max(got.traces_per_tile) < 0.6 * N and min(got.traces_per_tile) > 0


def test_a_tile_takes_every_trace_that_reaches_it_and_no_more():
    """Each trace that tile_traces leaves out of a tile adds exactly nothing to that tile's columns; and each trace
    it keeps, bar those in its 1 cm margin, does reach some voxel of the tile (its fold there is positive)."""
    o = op("numpy")
    tile = plan_tiles(GRID, 0.4)[7]
    keep = tile_traces(o, tile)
    out = np.setdiff1d(np.arange(N), keep)
    assert 0 < keep.size < N // 2
    np.testing.assert_array_equal(o.with_traces(out).adjoint(DATA[out], window=tile.window), 0.0)
    ones = np.ones((1, 160), np.float32)
    reached = np.array([o.with_traces([j]).adjoint(ones, window=tile.window).max() > 0 for j in keep])
    inner = tile_traces(o, tile, margin_m=-0.01)  # the traces at least 1 cm inside the reach
    assert set(inner) <= set(keep[reached])
    assert reached.sum() >= 0.9 * keep.size


def test_layered_velocity_travels_to_the_tiles():
    o = op()
    o.slow = effective_slowness(GRID.depth, layers=[(0.0, 4.0), (0.3, 12.0)])
    got = migrate_site(o, DATA, tile_m=0.8, with_fold=False)
    np.testing.assert_array_equal(got.image, o.adjoint(DATA))
    assert got.fold is None


def test_an_aperture_radius_narrows_each_tile_s_traces_and_keeps_the_image():
    """A radius (0.25 m) narrower than the cone at the grid's bottom: each tile takes fewer traces than with the
    cone alone, and the tiles put together are the whole image with that radius."""
    cone, capped = op(), op(aperture_m=0.25)
    assert capped.reach_m < cone.reach_m
    got = migrate_site(capped, DATA, tile_m=0.8)
    np.testing.assert_array_equal(got.image, capped.adjoint(DATA))
    wide = migrate_site(cone, DATA, tile_m=0.8)
    assert sum(got.traces_per_tile) < sum(wide.traces_per_tile)


def test_without_an_aperture_every_tile_takes_every_trace():
    o = op(aperture=None)
    got = migrate_site(o, DATA, tile_m=1.2)
    assert got.traces_per_tile == [N] * got.tiles
    np.testing.assert_array_equal(got.image, o.adjoint(DATA))


def test_a_stopped_run_resumes_from_its_finished_tiles(tmp_path):
    o = op()
    want = migrate_site(o, DATA, tile_m=0.8)
    ck = tmp_path / "tiles"
    first = migrate_site(o, DATA, tile_m=0.8, checkpoint=ck)
    files = sorted(ck.glob("*.npz"))
    assert len(files) == first.tiles == 9
    files[0].unlink()  # a tile never finished
    files[1].write_bytes(b"half a file")  # a tile cut short
    logged = []
    again = migrate_site(o, DATA, tile_m=0.8, checkpoint=ck, log=logged.append)
    assert again.resumed == 7 and len(again.traces_per_tile) == 2
    assert "resumed 7 of 9 tiles" in logged[0]
    np.testing.assert_array_equal(again.image, want.image)
    np.testing.assert_array_equal(again.fold, want.fold)
    # other data: the folder's tiles are not this survey's
    with pytest.raises(InvalidDataError, match="another survey"):
        migrate_site(o, DATA * 2, tile_m=0.8, checkpoint=ck)


def test_dask_workers_give_the_same_image():
    pytest.importorskip("distributed")
    o = op()
    want_img, want_fold = o.adjoint(DATA, with_fold=True)
    got = migrate_site(o, DATA, tile_m=0.8, workers=2, threads=1)
    assert "2 local worker" in got.workers
    np.testing.assert_array_equal(got.image, want_img)
    np.testing.assert_array_equal(got.fold, want_fold)


@pytest.mark.parametrize("kw, match", [({"workers": -1}, "workers"), ({"workers": 1.5}, "workers"),
                                       ({"threads": 0}, "threads"), ({"scheduler": "localhost:8786"}, "scheduler"),
                                       ({"tile_m": 0}, "tile size")])
def test_bad_arguments_are_named(kw, match):
    with pytest.raises(InvalidDataError, match=match):
        migrate_site(op(), DATA, **kw)


def test_bad_data_is_named():
    bad = DATA.copy()
    bad[3, 7] = np.nan
    with pytest.raises(InvalidDataError, match="NaN"):
        migrate_site(op(), bad)
    with pytest.raises(InvalidDataError, match="data must be"):
        migrate_site(op(), DATA[:10])


def test_a_given_in_process_client_runs_every_tile_and_gives_the_same_image(tmp_path):
    """A ``distributed.Client`` of threads in this process (so that every tile's work is seen here): the image, fold
    and per-tile trace counts equal the one-process run's; the client is left open; the checkpoint is written."""
    distributed = pytest.importorskip("distributed")
    o = op("numpy")
    one = migrate_site(o, DATA, tile_m=0.8)
    logged = []
    with distributed.Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=":0") as client:
        got = migrate_site(o, DATA, tile_m=0.8, client=client, checkpoint=tmp_path / "ck", log=logged.append)
        assert client.status == "running"  # left open
        assert got.workers == "the given client (1 worker(s))"
        again = migrate_site(o, DATA, tile_m=0.8, client=client, checkpoint=tmp_path / "ck", log=logged.append)
    np.testing.assert_array_equal(got.image, one.image)
    np.testing.assert_array_equal(got.fold, one.fold)
    assert sorted(got.traces_per_tile) == sorted(one.traces_per_tile) and got.tiles == one.tiles
    assert again.resumed == got.tiles and again.traces_per_tile == []
    np.testing.assert_array_equal(again.image, one.image)
    assert logged == [f"resumed {got.tiles} of {got.tiles} tiles from {tmp_path / 'ck'}"]
    assert sorted(p.name for p in (tmp_path / "ck").iterdir()) == sorted(
        ["checkpoint.json"] + [f"{t.name}.npz" for t in plan_tiles(GRID, 0.8)])
