"""Site-scale migration: the grid cut into tiles of columns, each migrated on its own (on Dask workers).

A tile needs only the traces whose aperture reaches it: those whose tx-rx midpoint lies within the operator's
reach (:attr:`~gpr3d.migration.operator.BackProjection.reach_m`, the cone's radius at the deepest voxel) of the tile's rectangle, the
"halo". So a worker holds one tile's image and fold and its traces, whatever the size of the site, and the
tiles run in parallel on a local cluster or on a real one (``scheduler="tcp://host:8786"``).

The result is bit for bit the image of one process: each column sums the same traces in the same order (the
operator's trace bins are anchored to whole multiples of their size; a tile's traces keep the survey's order).

Finished tiles can be kept in a folder (``checkpoint``): a run that stops (a killed job, a lost worker) resumes
where it stopped, redoing only the unfinished tiles.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.errors import InvalidDataError
from gpr3d.migration.operator import BackProjection

__all__ = ["DEFAULT_TILE_M", "SiteResult", "Tile", "check_settings", "migrate_site", "plan_tiles", "tile_traces"]

#: tile sides are whole multiples of the kernel's column tiles (8 columns)
_ALIGN = 8
#: the tile side (m) where none is given
DEFAULT_TILE_M = 5.0


@dataclass(frozen=True)
class Tile:
    """Columns ``ix0:ix1`` x ``iy0:iy1`` of the grid."""

    ix0: int
    ix1: int
    iy0: int
    iy1: int

    @property
    def window(self) -> tuple[int, int, int, int]:
        return (self.ix0, self.ix1, self.iy0, self.iy1)

    @property
    def name(self) -> str:
        return f"x{self.ix0:05d}-{self.ix1:05d}_y{self.iy0:05d}-{self.iy1:05d}"


@dataclass
class SiteResult:
    """The migrated image (and fold) of a whole grid, with how it was made."""

    image: np.ndarray
    fold: np.ndarray | None
    tiles: int
    resumed: int
    traces_per_tile: list
    wall_s: float
    workers: str


def plan_tiles(grid, tile_m: float) -> list[Tile]:
    """The grid's columns cut into square tiles of about ``tile_m`` metres (whole multiples of 8 columns)."""
    check_settings(tile_m=tile_m)
    n = max(_ALIGN, int(round(tile_m / max(grid.dx, grid.dy) / _ALIGN)) * _ALIGN)
    return [Tile(ix, min(ix + n, grid.nx), iy, min(iy + n, grid.ny))
            for ix in range(0, grid.nx, n) for iy in range(0, grid.ny, n)]


def tile_traces(op: BackProjection, tile: Tile, margin_m: float = 0.01) -> np.ndarray:
    """Indices (ascending) of the traces whose aperture can reach ``tile``: midpoint within reach (+ ``margin_m``)
    of its rectangle. Without an aperture every trace reaches every tile."""
    if not math.isfinite(op.reach_m):
        return np.arange(op.n_traces)
    mid = 0.5 * (op.tx[:, :2] + op.rx[:, :2])
    xa, xb = op.x[tile.ix0], op.x[tile.ix1 - 1]
    ya, yb = op.y[tile.iy0], op.y[tile.iy1 - 1]
    ex = np.maximum(np.maximum(xa - mid[:, 0], 0.0), mid[:, 0] - xb)
    ey = np.maximum(np.maximum(ya - mid[:, 1], 0.0), mid[:, 1] - yb)
    r = op.reach_m + margin_m
    return np.flatnonzero(ex * ex + ey * ey <= r * r)


def migrate_tile(op: BackProjection, tile: Tile, data, with_fold: bool, threads: int | None = None):
    """One tile's image (and fold): what a worker runs. ``op`` and ``data`` hold the tile's traces only."""
    if threads:
        import numba

        numba.set_num_threads(min(int(threads), numba.config.NUMBA_NUM_THREADS))
    t = time.perf_counter()
    if len(data) == 0:
        empty = np.zeros((tile.ix1 - tile.ix0, tile.iy1 - tile.iy0, op.grid.nd), np.float32)
        img, fold = empty, (empty.copy() if with_fold else None)
    else:
        out = op.adjoint(data, with_fold=with_fold, window=tile.window)
        img, fold = out if with_fold else (out, None)
    return {"tile": tile, "image": img, "fold": fold, "wall_s": time.perf_counter() - t, "pid": os.getpid()}


def check_settings(*, tile_m=DEFAULT_TILE_M, workers=0, scheduler=None, threads=None) -> None:
    """One line naming a wrong tile size, worker or thread count, or scheduler address."""
    try:
        ok = tile_m is None or (math.isfinite(float(tile_m)) and float(tile_m) > 0)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InvalidDataError(f"tile size must be a positive number of metres, got {tile_m}")
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 0:
        raise InvalidDataError(f"workers must be a whole number >= 0, got {workers!r}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, (int, np.integer))
                                or threads < 1):
        raise InvalidDataError(f"threads must be a whole number >= 1, got {threads!r}")
    if scheduler is not None and not str(scheduler).startswith(("tcp://", "tls://", "inproc://", "ucx://")):
        raise InvalidDataError(f"scheduler must be an address such as tcp://host:8786, got {scheduler!r}")


def _fingerprint(op: BackProjection, data, with_fold: bool, tiles: list[Tile]) -> str:
    h = hashlib.sha256()
    for a in (op.tx, op.rx, op.slow, np.ascontiguousarray(data, np.float32)):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps([op.grid.to_dict(), op.dt, op.n_samples, op.t0, op.tan_ap, op.aperture_m, op.obliquity, op.spreading,
                         with_fold, [t.window for t in tiles]], default=float).encode())
    return h.hexdigest()[:16]


class _Checkpoint:
    """Finished tiles as ``<folder>/<tile>.npz`` (each written atomically), for one survey and settings."""

    def __init__(self, folder, key: str):
        self.dir = Path(folder)
        self.dir.mkdir(parents=True, exist_ok=True)
        meta = self.dir / "checkpoint.json"
        if meta.exists():
            old = json.loads(meta.read_text()).get("key")
            if old != key:
                raise InvalidDataError(f"{self.dir} holds tiles of another survey or other settings; use another "
                                       "checkpoint folder or remove it")
        else:
            atomic_write_text(meta, json.dumps({"key": key}))

    def path(self, tile: Tile) -> Path:
        return self.dir / f"{tile.name}.npz"

    def load(self, tile: Tile):
        p = self.path(tile)
        if not p.exists():
            return None
        try:
            with np.load(p) as z:
                return z["image"], (z["fold"] if "fold" in z.files else None)
        except (OSError, ValueError, KeyError):  # a damaged file: redo that tile
            p.unlink(missing_ok=True)
            return None

    def save(self, tile: Tile, image, fold):
        tmp = self.path(tile).with_suffix(".part.npz")
        arrays = {"image": image} if fold is None else {"image": image, "fold": fold}
        np.savez(tmp, **arrays)
        os.replace(tmp, self.path(tile))


def _client(workers: int, scheduler: str | None, threads_per_worker: int):
    from gpr3d.core.deps import require

    distributed = require("distributed")
    if scheduler:
        return distributed.Client(scheduler), None
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker, processes=True,
                                       dashboard_address=":0", silence_logs=40)
    return distributed.Client(cluster), cluster


def migrate_site(op: BackProjection, data, *, tile_m: float = DEFAULT_TILE_M, with_fold: bool = True,
                 workers: int = 0, scheduler: str | None = None, threads: int | None = None, checkpoint=None, client=None,
                 log=None) -> SiteResult:
    """The adjoint of ``op`` (and its fold) over its whole grid, tile by tile.

    ``workers = 0`` and no ``scheduler``: the tiles run one after the other in this process (memory bounded by
    one tile, the image aside). ``workers >= 1``: a local Dask cluster of that many processes, each running the
    numba kernel on ``threads`` threads (default: this machine's cores shared out). ``scheduler``: the address
    of a running Dask scheduler. ``checkpoint``: a folder keeping finished tiles; a second run with the same
    survey and settings loads them and migrates only the rest. ``client``: a ``distributed.Client`` to use as it
    is (left open).
    """
    data = np.asarray(data, dtype=np.float32)
    if data.shape != (op.n_traces, op.n_samples):
        raise InvalidDataError(f"data must be {(op.n_traces, op.n_samples)}, got {data.shape}")
    if not np.all(np.isfinite(data)):
        raise InvalidDataError("the data hold NaN or infinite samples: nothing can be migrated from them")
    check_settings(tile_m=tile_m, workers=workers, scheduler=scheduler, threads=threads)
    log = log or (lambda msg: None)
    t_start = time.perf_counter()
    g = op.grid
    tiles = plan_tiles(g, tile_m)
    image = np.zeros(g.shape, np.float32)
    fold = np.zeros(g.shape, np.float32) if with_fold else None
    ckpt = _Checkpoint(checkpoint, _fingerprint(op, data, with_fold, tiles)) if checkpoint else None
    todo, resumed = [], 0
    for tile in tiles:
        got = ckpt.load(tile) if ckpt else None
        if got is not None and (not with_fold or got[1] is not None):
            _place(image, fold, tile, *got)
            resumed += 1
        else:
            todo.append(tile)
    if resumed:
        log(f"resumed {resumed} of {len(tiles)} tiles from {checkpoint}")
    counts = []

    def finish(res):
        _place(image, fold, res["tile"], res["image"], res["fold"])
        if ckpt:
            ckpt.save(res["tile"], res["image"], res["fold"])

    def parts(tile):
        idx = tile_traces(op, tile)
        counts.append(int(idx.size))
        return op.with_traces(idx), data[idx]

    if workers == 0 and scheduler is None and client is None:
        mode = "this process"
        for tile in todo:
            sub, d = parts(tile)
            finish(migrate_tile(sub, tile, d, with_fold, threads))
    else:
        # numba threads per worker: this machine's cores shared out on a local cluster; elsewhere as given (None:
        # numba's default on each worker)
        per = threads or (max(1, (os.cpu_count() or 1) // workers) if workers and not scheduler and client is None
                          else None)
        own = client is None
        client, cluster = _client(workers, scheduler, 1) if own else (client, None)
        if not own:
            n = len(client.scheduler_info().get("workers", {}))
            mode = f"the given client ({n} worker(s))"
        else:
            mode = scheduler or f"{workers} local worker(s) x {per} thread(s)"
        try:
            from gpr3d.core.deps import require

            distributed = require("distributed")
            # a bounded number of tiles in flight (two per worker): a worker holds one or two tiles' traces and
            # images at a time, whatever the size of the site
            n_workers = max(1, len(client.scheduler_info().get("workers", {})))
            queue = list(todo)

            def submit(tile):
                sub, d = parts(tile)
                return client.submit(migrate_tile, sub, tile, client.scatter(d), with_fold, per, pure=False)

            running = distributed.as_completed([submit(queue.pop(0)) for _ in range(min(2 * n_workers, len(queue)))])
            for fut in running:
                finish(fut.result())
                fut.release()
                if queue:
                    running.add(submit(queue.pop(0)))
        finally:
            if own:
                client.close()
            if cluster is not None:
                cluster.close()
    return SiteResult(image=image, fold=fold, tiles=len(tiles), resumed=resumed, traces_per_tile=counts,
                      wall_s=time.perf_counter() - t_start, workers=mode)


def _place(image, fold, tile: Tile, img, fld):
    image[tile.ix0:tile.ix1, tile.iy0:tile.iy1] = img
    if fold is not None:
        fold[tile.ix0:tile.ix1, tile.iy0:tile.iy1] = fld
