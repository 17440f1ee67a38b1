"""Site tiles by hand: the settings' messages, the Dask plumbing against a recording stand-in for ``distributed``
(what is submitted, how many tiles are in flight, what is closed), one tile's work, and the checkpoint's contract.

The stand-in runs each submitted tile at once in this process, so the image it gives must still be the one-process
image bit for bit; every call it receives is recorded and compared with what the settings imply.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest

import gpr3d.core.deps as deps
from gpr3d.core.errors import InvalidDataError
from gpr3d.migration import sitetiles
from gpr3d.migration.sitetiles import Tile, check_settings, migrate_site, migrate_tile, plan_tiles, tile_traces
from tests.migration.test_sitetiles import DATA, GRID, N, op


class _Future:
    def __init__(self, value):
        self.value, self.released = value, False

    def result(self):
        return self.value

    def release(self):
        self.released = True


class _AsCompleted:
    """Yields the futures in the order they were added; records how many were pending at most."""

    def __init__(self, book, futures):
        self.book, self.pending = book, list(futures)
        book["in_flight"] = max(book.get("in_flight", 0), len(self.pending))

    def add(self, fut):
        self.pending.append(fut)
        self.book["in_flight"] = max(self.book["in_flight"], len(self.pending))

    def __iter__(self):
        while self.pending:
            yield self.pending.pop(0)


class _Client:
    def __init__(self, book, n_workers, target=None):
        self.book, self.n_workers, self.target, self.closed = book, n_workers, target, False
        self.submitted, self.scattered = [], []

    def scheduler_info(self):
        return {"workers": {f"w{i}": {} for i in range(self.n_workers)}}

    def scatter(self, d):
        self.scattered.append(d)
        return ("scattered", len(self.scattered) - 1)

    def submit(self, fn, *args, **kwargs):
        self.submitted.append((fn, args, kwargs))
        sub, tile, handle, with_fold, per = args
        return _Future(fn(sub, tile, self.scattered[handle[1]], with_fold, None))  # threads left alone here

    def close(self):
        self.closed = True


def _fake_distributed(monkeypatch, n_workers=2):
    """A recording stand-in for ``distributed``, returned by ``gpr3d.core.deps.require('distributed')``."""
    book = {"clients": [], "clusters": []}

    class LocalCluster:
        def __init__(self, **kwargs):
            self.kwargs, self.closed = kwargs, False
            book["clusters"].append(self)

        def close(self):
            self.closed = True

    def Client(target):
        c = _Client(book, n_workers, target)
        book["clients"].append(c)
        return c

    fake = SimpleNamespace(LocalCluster=LocalCluster, Client=Client,
                           as_completed=lambda futures: _AsCompleted(book, futures))
    monkeypatch.setattr(deps, "require", lambda name: {"distributed": fake}[name])
    return book


def test_a_local_cluster_is_made_as_the_settings_say_and_closed(monkeypatch):
    book = _fake_distributed(monkeypatch, n_workers=3)
    monkeypatch.setattr(sitetiles.os, "cpu_count", lambda: 8)
    o = op("numpy")
    one = migrate_site(o, DATA, tile_m=0.4)
    got = migrate_site(o, DATA, tile_m=0.4, workers=3)
    (cluster,), (client,) = book["clusters"], book["clients"]
    assert cluster.kwargs == {"n_workers": 3, "threads_per_worker": 1, "processes": True, "dashboard_address": ":0",
                              "silence_logs": 40}
    assert client.target is cluster and client.closed and cluster.closed
    assert got.workers == "3 local worker(s) x 2 thread(s)"  # 8 cores // 3 workers
    # every tile submitted once, with its own traces, the numba threads per worker, and not cached by Dask
    tiles = plan_tiles(GRID, 0.4)
    assert [args[1] for _, args, _ in client.submitted] == tiles
    for (fn, (sub, tile, handle, with_fold, per), kwargs), d in zip(client.submitted, client.scattered):
        idx = tile_traces(o, tile)
        assert fn is sitetiles.migrate_tile and kwargs == {"pure": False} and with_fold is True and per == 2
        np.testing.assert_array_equal(sub.tx, o.tx[idx])
        np.testing.assert_array_equal(d, DATA[idx])
    assert len(client.scattered) == len(tiles)
    # two tiles per worker in flight at most, and as many as that
    assert book["in_flight"] == 6
    np.testing.assert_array_equal(got.image, one.image)
    np.testing.assert_array_equal(got.fold, one.fold)
    assert got.traces_per_tile == one.traces_per_tile


@pytest.mark.parametrize("workers, cores, per", [(2, 8, 4), (3, 1, 1), (2, None, 1), (1, None, 1), (1, 5, 5)])
def test_threads_per_local_worker_share_out_the_cores(monkeypatch, workers, cores, per):
    book = _fake_distributed(monkeypatch, n_workers=workers)
    monkeypatch.setattr(sitetiles.os, "cpu_count", lambda: cores)
    got = migrate_site(op("numpy"), DATA, tile_m=1.2, workers=workers, with_fold=False)
    assert {args[4] for _, args, _ in book["clients"][0].submitted} == {per}
    assert got.workers == f"{workers} local worker(s) x {per} thread(s)"
    assert book["in_flight"] == min(2 * workers, got.tiles)


def test_given_threads_go_to_every_tile(monkeypatch):
    book = _fake_distributed(monkeypatch, n_workers=1)
    got = migrate_site(op("numpy"), DATA, tile_m=0.8, workers=2, threads=3, with_fold=False)
    assert [args[4] for _, args, _ in book["clients"][0].submitted] == [3] * got.tiles
    assert got.workers == "2 local worker(s) x 3 thread(s)"
    assert book["in_flight"] == 2 and got.fold is None


def test_a_scheduler_address_is_connected_to_and_closed_without_a_cluster(monkeypatch):
    book = _fake_distributed(monkeypatch, n_workers=1)
    o = op("numpy")
    got = migrate_site(o, DATA, tile_m=0.8, scheduler="tcp://example:8786")
    (client,) = book["clients"]
    assert client.target == "tcp://example:8786" and client.closed and book["clusters"] == []
    assert got.workers == "tcp://example:8786"
    assert {args[4] for _, args, _ in client.submitted} == {None}  # numba's default on each worker
    assert book["in_flight"] == 2
    np.testing.assert_array_equal(got.image, o.adjoint(DATA))


def test_a_given_client_is_used_as_it_is_and_left_open(monkeypatch):
    book = _fake_distributed(monkeypatch)
    given = _Client(book, 4)
    o = op("numpy")
    got = migrate_site(o, DATA, tile_m=0.4, client=given, workers=1)
    assert book["clients"] == [] and book["clusters"] == [] and not given.closed
    assert got.workers == "the given client (4 worker(s))"
    assert {args[4] for _, args, _ in given.submitted} == {None}
    assert book["in_flight"] == 8
    np.testing.assert_array_equal(got.image, o.adjoint(DATA))
    given2 = _Client(book, 0)  # a scheduler with no workers yet: still one pair of tiles in flight
    book["in_flight"] = 0
    migrate_site(o, DATA, tile_m=0.8, client=given2, threads=2)
    assert book["in_flight"] == 2 and {args[4] for _, args, _ in given2.submitted} == {2}
    assert len(given2.submitted) == 9


def test_the_default_runs_in_this_process_with_float32_images():
    o = op("numpy")
    got = migrate_site(o, DATA.astype(np.float64), tile_m=0.8)
    assert got.workers == "this process" and got.resumed == 0
    assert got.image.dtype == np.float32 and got.fold.dtype == np.float32
    np.testing.assert_array_equal(got.image, o.adjoint(DATA))
    assert 0 < got.wall_s < 600


def test_one_tile_of_work():
    o = op("numpy")
    tile = Tile(8, 16, 16, 24)
    idx = tile_traces(o, tile)
    sub = o.with_traces(idx)
    got = migrate_tile(sub, tile, DATA[idx], True)
    assert set(got) == {"tile", "image", "fold", "wall_s", "pid"}
    want_img, want_fold = o.adjoint(DATA, with_fold=True, window=tile.window)
    np.testing.assert_array_equal(got["image"], want_img)
    np.testing.assert_array_equal(got["fold"], want_fold)
    assert got["tile"] is tile and got["pid"] == sitetiles.os.getpid() and 0 <= got["wall_s"] < 600
    # one trace is work, not an empty tile
    j = idx[:1]
    one = migrate_tile(o.with_traces(j), tile, DATA[j], False)
    np.testing.assert_array_equal(one["image"], o.with_traces(j).adjoint(DATA[j], window=tile.window))
    assert np.abs(one["image"]).max() > 0 and one["fold"] is None
    # no traces: zeros of the tile's shape, the fold a separate array
    none = migrate_tile(o.with_traces(idx[:0]), tile, DATA[idx[:0]], True)
    assert none["image"].shape == none["fold"].shape == (8, 8, GRID.nd)
    assert none["image"].dtype == none["fold"].dtype == np.float32
    assert not none["image"].any() and not none["fold"].any() and none["fold"] is not none["image"]
    edge = Tile(40, 45, 32, 37)
    assert migrate_tile(o.with_traces(idx[:0]), edge, DATA[:0], False)["image"].shape == (5, 5, GRID.nd)
    assert migrate_tile(o.with_traces(idx[:0]), edge, DATA[:0], False)["fold"] is None


def test_threads_in_this_process_go_to_every_tile(monkeypatch):
    import numba

    calls = []
    monkeypatch.setattr(numba, "set_num_threads", calls.append)
    got = migrate_site(op("numpy"), DATA, tile_m=0.8, threads=1)
    assert got.workers == "this process" and calls == [1] * got.tiles
    calls.clear()
    migrate_site(op("numpy"), DATA, tile_m=0.8)
    assert calls == []


def test_a_tile_sets_the_numba_threads_it_is_given(monkeypatch):
    import numba

    calls = []
    monkeypatch.setattr(numba, "set_num_threads", calls.append)
    o = op("numpy")
    tile = Tile(0, 8, 0, 8)
    migrate_tile(o, tile, DATA, False, np.int64(1))
    migrate_tile(o, tile, DATA, False, 10 ** 6)
    migrate_tile(o, tile, DATA, False)
    assert calls == [1, numba.config.NUMBA_NUM_THREADS]


def test_a_trace_exactly_at_the_reach_is_taken():
    """A stand-in operator with a 0.5 m reach over columns 0.25 m apart: the tile of columns 0..3 (x and y up to
    0.75 m) takes the midpoints up to 0.5 m from its rectangle, the boundary included (3/8, 1/2 -> 5/8 m)."""
    x = np.arange(10) * 0.25
    mids = np.array([[1.25, 0.5], [1.2500001, 0.5], [0.75 + 0.375, 0.75 + 0.5], [0.75 + 0.375, 0.75 + 0.5001],
                     [-0.5, 0.0], [0.3, -0.5000001], [0.3, 0.3]])
    pts = np.c_[mids, np.zeros(len(mids))]
    fake = SimpleNamespace(reach_m=0.5, tx=pts - [0.125, 0, 0], rx=pts + [0.125, 0, 0], x=x, y=x, n_traces=len(mids))
    tile = Tile(0, 4, 0, 4)
    np.testing.assert_array_equal(tile_traces(fake, tile, margin_m=0.0), [0, 4, 6])
    np.testing.assert_array_equal(tile_traces(fake, tile, margin_m=0.125), [0, 1, 2, 4, 5, 6])
    np.testing.assert_array_equal(tile_traces(fake, tile), [0, 1, 4, 5, 6])  # the 1 cm margin by default
    fake.reach_m = float("inf")
    np.testing.assert_array_equal(tile_traces(fake, tile), np.arange(7))


def test_tile_names_and_windows():
    t = Tile(8, 16, 0, 5)
    assert t.window == (8, 16, 0, 5)
    assert t.name == "x00008-00016_y00000-00005"


@pytest.mark.parametrize("kw, msg", [
    ({"tile_m": 0}, "tile size must be a positive number of metres, got 0"),
    ({"tile_m": float("inf")}, "tile size must be a positive number of metres, got inf"),
    ({"tile_m": "wide"}, "tile size must be a positive number of metres, got wide"),
    ({"tile_m": [5.0]}, "tile size must be a positive number of metres, got [5.0]"),
    ({"workers": -1}, "workers must be a whole number >= 0, got -1"),
    ({"workers": 2.0}, "workers must be a whole number >= 0, got 2.0"),
    ({"workers": True}, "workers must be a whole number >= 0, got True"),
    ({"threads": 0}, "threads must be a whole number >= 1, got 0"),
    ({"threads": 2.0}, "threads must be a whole number >= 1, got 2.0"),
    ({"threads": True}, "threads must be a whole number >= 1, got True"),
    ({"scheduler": "localhost:8786"}, "scheduler must be an address such as tcp://host:8786, got 'localhost:8786'"),
    ({"scheduler": "TCP://h:1"}, "scheduler must be an address such as tcp://host:8786, got 'TCP://h:1'"),
])
def test_check_settings_names_each_wrong_value_in_full(kw, msg):
    with pytest.raises(InvalidDataError) as err:
        check_settings(**kw)
    assert str(err.value) == msg


@pytest.mark.parametrize("kw", [{}, {"tile_m": None}, {"tile_m": "2.5"}, {"tile_m": 1e-3}, {"workers": 0},
                                {"workers": np.int64(4)}, {"threads": 1}, {"threads": np.int32(2)},
                                {"scheduler": "tcp://h:8786"}, {"scheduler": "tls://h:8786"},
                                {"scheduler": "inproc://192.168.1.2/1/3"}, {"scheduler": "ucx://h:13337"}])
def test_check_settings_lets_good_values_through(kw):
    assert check_settings(**kw) is None


def test_bad_data_messages_in_full():
    bad = DATA.copy()
    bad[0, 0] = np.inf
    with pytest.raises(InvalidDataError) as err:
        migrate_site(op(), bad)
    assert str(err.value) == "the data hold NaN or infinite samples: nothing can be migrated from them"
    with pytest.raises(InvalidDataError) as err:
        migrate_site(op(), DATA[:, :100])
    assert str(err.value) == f"data must be {(N, 160)}, got {(N, 100)}"


def test_a_checkpoint_without_folds_resumes_and_one_with_other_settings_is_refused(tmp_path):
    o = op("numpy")
    ck = tmp_path / "site" / "run1" / "tiles"  # parents made as needed
    first = migrate_site(o, DATA, tile_m=0.8, with_fold=False, checkpoint=ck)
    assert first.resumed == 0 and first.fold is None
    t = plan_tiles(GRID, 0.8)[4]
    with np.load(ck / f"{t.name}.npz") as z:
        assert z.files == ["image"]
        np.testing.assert_array_equal(z["image"], first.image[t.ix0:t.ix1, t.iy0:t.iy1])
    again = migrate_site(o, DATA, tile_m=0.8, with_fold=False, checkpoint=ck)
    assert again.resumed == again.tiles == 9 and again.traces_per_tile == []
    np.testing.assert_array_equal(again.image, o.adjoint(DATA))
    assert not list(ck.glob("*.part.npz"))
    # the same survey with a fold, or with other migration settings: not these tiles
    for other, kw in [(o, {"with_fold": True}), (op("numpy", aperture=25.0), {"with_fold": False})]:
        with pytest.raises(InvalidDataError) as err:
            migrate_site(other, DATA, tile_m=0.8, checkpoint=ck, **kw)
        assert str(err.value) == (f"{ck} holds tiles of another survey or other settings; use another checkpoint "
                                  "folder or remove it")
    key = json.loads((ck / "checkpoint.json").read_text())["key"]
    assert len(key) == 16 and set(key) <= set("0123456789abcdef")


def test_the_checkpoint_key_follows_every_setting():
    """The key changes with each of the operator's settings, the data, the fold and the tiles: a folder of
    tiles made otherwise is never mistaken for this run's."""
    o = op("numpy")
    tiles = plan_tiles(GRID, 0.8)
    base = sitetiles._fingerprint(o, DATA, True, tiles)
    assert base == sitetiles._fingerprint(op("numpy"), DATA.copy(), True, list(tiles))
    variants = [(o, DATA[::-1].copy(), True, tiles), (o, DATA, False, tiles), (o, DATA, True, tiles[:-1]),
                (o, DATA, True, plan_tiles(GRID, 0.4))]
    for attr, value in [("dt", 0.2e-9), ("n_samples", 150), ("t0", 0.6e-9), ("obliquity", False),
                        ("spreading", False), ("tan_ap", 0.5), ("aperture_m", 0.3)]:
        changed = op("numpy")
        setattr(changed, attr, value)
        variants.append((changed, DATA, True, tiles))
    moved = op("numpy")
    moved.tx = moved.tx + [0.01, 0, 0]
    variants.append((moved, DATA, True, tiles))
    moved = op("numpy")
    moved.rx = moved.rx + [0, 0.01, 0]
    variants.append((moved, DATA, True, tiles))
    slower = op("numpy")
    slower.slow = slower.slow * 1.01
    variants.append((slower, DATA, True, tiles))
    shifted = op("numpy")
    shifted.grid = GRID.__class__(**{**GRID.to_dict(), "d0": GRID.d0 + 0.01})
    variants.append((shifted, DATA, True, tiles))
    keys = [sitetiles._fingerprint(*v) for v in variants]
    assert base not in keys and len(set(keys)) == len(keys)
