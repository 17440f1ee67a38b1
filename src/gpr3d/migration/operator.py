"""3D diffraction-stack migration from arbitrary antenna poses, as a linear operator.

For trace ``j`` (transmitter ``a_j``, receiver ``b_j``, from the pose: the tx-rx
offset rotates with the antenna heading) and voxel ``p`` at depth ``d``::

    t_j(p) = t0 + (|a_j - p| + |p - b_j|) / v_eff(d)

The antennas' z is the elevation of the ground under them (0 on flat ground; a higher antenna has that much more
ground above the voxel, as in the static correction). An antenna held ``g`` above the ground (``air_gap_m``: a
horn antenna, a cart with a gap) adds an air leg: each leg then refracts at the surface, its time the least over
the crossing point (Fermat; :mod:`gpr3d.core.raypath`).

``forward`` (demigration, diffraction summation) spreads each voxel's value onto
every trace at ``t_j(p)`` by linear interpolation; ``adjoint`` (migration, back
projection) gathers ``data_j(t_j(p))`` into the voxel (a trace reads as zero past its last
sample). They are exact adjoints
(dot-tested). Options: an aperture (a beam half-angle from the vertical, seen
from the antenna midpoint), an obliquity weight ``cos(theta)`` and a spreading
weight ``r``. ``v_eff(d)`` is constant or, for layers, the vertical average
velocity down to ``d`` (straight rays).

Engines: ``"numba"`` (parallel kernels in ``gpr3d.migration._kernels``; the adjoint's depth loop
in explicit SIMD, ``gpr3d.migration._simd``) and ``"numpy"`` (the readable reference below,
vectorised over voxels, one trace at a time).
"""

from __future__ import annotations

import copy
import math
import os

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.poses import quat_from_yaw, rotate_vectors
from gpr3d.core.raypath import S_AIR, air_ground_times
from gpr3d.core.units import C0
from gpr3d.core.grid import Grid3D

__all__ = ["BackProjection", "antenna_positions", "check_engine", "effective_slowness", "dot_test"]


def check_engine(engine: str) -> tuple:
    """A back projection engine's name checked, its device too, before any work.

    Parameters
    ----------
    engine : str
        ``"numba"``, ``"numpy"``, ``"torch"`` (PyTorch on the CPU), ``"torch:cuda"`` or ``"torch:cuda:N"``.

    Returns
    -------
    tuple of (str, str or None)
        The engine (``"numba"``, ``"numpy"`` or ``"torch"``) and, for torch, its device (``"cpu"``, ``"cuda:0"``).

    Raises
    ------
    InvalidDataError
        An unknown engine, a device for another engine than torch, or a device that is not here.
    """
    base, _, device = str(engine).partition(":")
    if base not in BackProjection._ENGINES or (device and base != "torch"):
        raise InvalidDataError(f"engine must be one of {', '.join(map(repr, BackProjection._ENGINES))} (or "
                               f"'torch:cuda', 'torch:cuda:N'), got {engine!r}")
    if base != "torch":
        return base, None
    from gpr3d.migration._torch import check_device

    return base, check_device(device or "cpu")


def antenna_positions(positions_xyz, orientations_quat_wxyz=None, offset_m: float = 0.0, headings_rad=None):
    """Transmitter and receiver positions of each trace: ``-/+ offset/2`` along the antenna's x axis.

    Parameters
    ----------
    positions_xyz : array_like, (n, 3)
        The antenna's centre per trace (world, m).
    orientations_quat_wxyz : array_like, (n, 4), optional
        The antenna's orientation per trace; default: from ``headings_rad`` (or none: x along world x).
    offset_m : float
        Transmitter-receiver offset.
    headings_rad : float or array_like, optional
        Yaw per trace (or one for all), where no orientations are given.

    Returns
    -------
    tuple of ndarray
        ``(tx, rx)``, each ``(n, 3)`` float64, C-contiguous.
    """
    p = np.asarray(positions_xyz, dtype=np.float64).reshape(-1, 3)
    if orientations_quat_wxyz is None:
        yaw = np.zeros(len(p)) if headings_rad is None else np.broadcast_to(np.asarray(headings_rad, float), (len(p),))
        q = quat_from_yaw(yaw)
    else:
        q = np.asarray(orientations_quat_wxyz, dtype=np.float64).reshape(-1, 4)
    half = rotate_vectors(q, np.array([offset_m / 2, 0.0, 0.0]))
    return np.ascontiguousarray(p - half), np.ascontiguousarray(p + half)


def effective_slowness(depth: np.ndarray, eps_r=None, layers=None) -> np.ndarray:
    """``1 / v_eff(d)`` per depth: constant ``eps_r``, or ``layers = [(top_depth_m, eps_r), ...]``.

    For layers the vertical travel time down to ``d`` divided by ``d`` (straight rays).
    """
    depth = np.asarray(depth, dtype=np.float64)
    if layers is None:
        if eps_r is None:
            raise InvalidDataError("give eps_r or layers for the migration velocity")
        return np.full(depth.shape, math.sqrt(eps_r) / C0)
    tops = np.array([lay[0] for lay in layers], float)
    eps = np.array([lay[1] for lay in layers], float)
    if tops[0] != 0 or np.any(np.diff(tops) <= 0):
        raise InvalidDataError("layers must start at depth 0 and deepen")
    out = np.empty_like(depth)
    for i, d in enumerate(depth):
        bottoms = np.append(tops[1:], np.inf)
        thick = np.clip(np.minimum(bottoms, d) - tops, 0, None)
        out[i] = np.sum(thick * np.sqrt(eps)) / C0 / d if d > 0 else math.sqrt(eps[0]) / C0
    return out


class BackProjection:
    """The diffraction-stack operator between data ``(n_traces, n_samples)`` and images on a grid.

    Parameters
    ----------
    grid : :class:`~gpr3d.core.grid.Grid3D`
    tx, rx : ``(n_traces, 3)`` transmitter and receiver positions (world, m; z = the elevation of the ground under
        the antenna, 0 on flat ground)
    dt_s, n_samples : the data's time axis; ``t0_s`` is time zero (s after the first sample)
    eps_r / layers : the velocity (see :func:`effective_slowness`)
    aperture_deg : beam half-angle from the vertical (None: no limit)
    aperture_m : the aperture's horizontal radius (m): a trace reaches only the columns within it of its tx-rx
        midpoint, at any depth (None: no limit; with ``aperture_deg``, whichever is narrower)
    obliquity, spreading : weights ``cos(theta)`` and ``r``
    air_gap_m : the antennas' height above the ground (m): one number or one per trace (0: ground-coupled)
    engine : ``"numba"``, ``"numpy"``, or ``"torch"`` (PyTorch on the CPU; ``"torch:cuda"``, ``"torch:cuda:N"`` on
        a GPU)

    Raises
    ------
    InvalidDataError
        Positions that are not ``(n_traces, 3)`` each, an unknown engine, an air gap of the wrong shape, or a
        velocity that cannot be used.
    """

    def __init__(self, grid: Grid3D, tx, rx, *, dt_s: float, n_samples: int, t0_s: float = 0.0, eps_r=None,
                 layers=None, aperture_deg: float | None = None, aperture_m: float | None = None,
                 obliquity: bool = False, spreading: bool = False, air_gap_m=0.0, engine: str = "numba"):
        self.grid = grid
        self.tx = np.ascontiguousarray(tx, dtype=np.float64)
        self.rx = np.ascontiguousarray(rx, dtype=np.float64)
        if self.tx.shape != self.rx.shape or self.tx.ndim != 2 or self.tx.shape[1] != 3:
            raise InvalidDataError("tx and rx must both be (n_traces, 3)")
        base, device = check_engine(engine)
        gap = np.asarray(air_gap_m, dtype=np.float64)
        if gap.ndim > 1 or (gap.ndim == 1 and gap.shape != (self.tx.shape[0],)):
            raise InvalidDataError(f"air_gap_m must be one number or one per trace ({self.tx.shape[0]}), got shape "
                                   f"{gap.shape}")
        if not np.all(np.isfinite(gap)) or np.any(gap < 0):
            raise InvalidDataError("air_gap_m must be finite and >= 0 (the antennas' height above the ground, m)")
        self.air_gap = np.ascontiguousarray(np.broadcast_to(gap, (self.tx.shape[0],)))
        self.torch_device = device
        if base == "torch":
            if np.any(self.air_gap > 0):
                raise InvalidDataError("the torch engine has no air gap (rays refracted at the surface): use "
                                       "engine 'numba' for an antenna above the ground")
        self.dt = float(dt_s)
        self.n_samples = int(n_samples)
        self.t0 = float(t0_s)
        self.slow = effective_slowness(grid.depth, eps_r, layers)
        self.tan_ap = 0.0 if aperture_deg is None else math.tan(math.radians(aperture_deg))
        if aperture_m is not None and not (isinstance(aperture_m, (int, float)) and not isinstance(aperture_m, bool)
                                           and math.isfinite(aperture_m) and aperture_m > 0):
            raise InvalidDataError(f"aperture_m must be a positive number of metres (or None: no limit), got "
                                   f"{aperture_m!r}")
        self.aperture_m = None if aperture_m is None else float(aperture_m)
        self.obliquity = bool(obliquity)
        self.spreading = bool(spreading)
        self.engine = base
        # the numba engine's adjoint uses the explicit-SIMD kernel where it compiles; GPR3D_SIMD=0 turns it off
        self.simd = os.environ.get("GPR3D_SIMD", "1") != "0"
        # how the SIMD loop reads traces: None = by the CPU (:func:`._kernels.read_path`), True = hardware gathers,
        # False = scalar loads
        self.gather = None
        # with an aperture, the tiled adjoint (cost that follows the aperture); GPR3D_TILED=0 turns it off
        self.tiled = os.environ.get("GPR3D_TILED", "1") != "0"
        self.x = grid.x.astype(np.float64)
        self.y = grid.y.astype(np.float64)
        self.depth = grid.depth.astype(np.float64)

    @property
    def n_traces(self) -> int:
        return self.tx.shape[0]

    @property
    def shape(self):
        return (self.n_traces * self.n_samples, self.grid.size)

    # ---------------------------------------------------------------- numpy reference
    def _window(self, window):
        """The column coordinates of ``window = (ix0, ix1, iy0, iy1)`` (None: the whole grid), checked."""
        if window is None:
            return self.x, self.y
        ix0, ix1, iy0, iy1 = (int(v) for v in window)
        if not (0 <= ix0 < ix1 <= self.grid.nx and 0 <= iy0 < iy1 <= self.grid.ny):
            raise InvalidDataError(f"window {tuple(window)} does not lie inside the {self.grid.nx} x {self.grid.ny} "
                                   "columns of the grid")
        return self.x[ix0:ix1], self.y[iy0:iy1]

    def _times_weights(self, j, xs=None, ys=None):
        xs = self.x if xs is None else xs
        ys = self.y if ys is None else ys
        X, Y, D = np.meshgrid(xs, ys, self.depth, indexing="ij")
        za, zb = D + self.tx[j, 2], D + self.rx[j, 2]
        ha2 = (X - self.tx[j, 0]) ** 2 + (Y - self.tx[j, 1]) ** 2
        hb2 = (X - self.rx[j, 0]) ** 2 + (Y - self.rx[j, 1]) ** 2
        g = self.air_gap[j]
        if g > 0:  # each leg refracts at the surface; the weights' legs run up to the antennas
            s = self.slow[None, None, :]
            u = (self.t0 + air_ground_times(g, za, np.sqrt(ha2), S_AIR, s)
                 + air_ground_times(g, zb, np.sqrt(hb2), S_AIR, s)) / self.dt
            za, zb = za + g, zb + g
            ra, rb = np.sqrt(ha2 + za**2), np.sqrt(hb2 + zb**2)
        else:
            ra, rb = np.sqrt(ha2 + za**2), np.sqrt(hb2 + zb**2)
            u = (self.t0 + (ra + rb) * self.slow[None, None, :]) / self.dt
        w = np.ones_like(u)
        if self.obliquity:
            w *= 0.5 * (za / np.maximum(ra, 1e-12) + zb / np.maximum(rb, 1e-12))  # r = 0 at an antenna: cos 0
        if self.spreading:
            w *= 0.5 * (ra + rb)
        if self.tan_ap > 0 or self.aperture_m is not None:
            hm = np.hypot(X - 0.5 * (self.tx[j, 0] + self.rx[j, 0]), Y - 0.5 * (self.tx[j, 1] + self.rx[j, 1]))
            if self.tan_ap > 0:  # the kernels start at the first depth sample at or below hm / tan
                kmin = np.ceil((hm / self.tan_ap - self.depth[0]) / self.grid.dd - 1e-12)
                w = np.where(np.arange(len(self.depth))[None, None, :] >= kmin, w, 0.0)
            if self.aperture_m is not None:  # and nothing beyond the aperture's radius
                w = np.where(hm <= self.aperture_m, w, 0.0)
        u = np.clip(u, 0.0, self.n_samples)  # past the end: the zero padding
        i0 = np.floor(u).astype(np.int64)
        return u, i0, w

    def _adjoint_numpy(self, data, xs=None, ys=None):
        xs = self.x if xs is None else xs
        ys = self.y if ys is None else ys
        img = np.zeros((len(xs), len(ys), self.grid.nd), dtype=np.float64)
        for j in range(self.n_traces):
            u, i0, w = self._times_weights(j, xs, ys)
            f = u - i0
            row = np.concatenate([data[j].astype(np.float64), [0.0, 0.0]])
            img += w * (row[i0] + f * (row[i0 + 1] - row[i0]))
        return img.astype(np.float32)

    def _forward_numpy(self, image):
        out = np.zeros((self.n_traces, self.n_samples + 2), dtype=np.float64)
        m = image.astype(np.float64)
        for j in range(self.n_traces):
            u, i0, w = self._times_weights(j)
            f = u - i0
            val = w * m
            np.add.at(out[j], i0.ravel(), ((1 - f) * val).ravel())
            np.add.at(out[j], i0.ravel() + 1, (f * val).ravel())
        return out[:, : self.n_samples].astype(np.float32)

    # ---------------------------------------------------------------- public
    def adjoint(self, data, *, with_fold: bool = False, window=None, depth_range=None):
        """Migration: data ``(n_traces, n_samples)`` -> image ``(nx, ny, nd)`` float32.

        ``with_fold``: also the fold, the adjoint of a trace of ones (how many traces see each voxel inside their
        aperture and record, weighted), returned as ``(image, fold)``; with an aperture the numba engine sums it in
        the same pass, otherwise it is a second migration. ``window = (ix0, ix1, iy0, iy1)``: only those columns
        of the grid (an image of ``(ix1 - ix0, iy1 - iy0, nd)``, equal to that part of the whole image; what
        :mod:`.sitetiles` gives each tile). ``depth_range`` ``(nx, ny, 2)`` integers (over the window's columns):
        each column's voxels ``[lo, hi)`` only, the others 0 (image and fold); the numba engine with an aperture
        then does only that work (what coarse-to-fine imaging refines), the others migrate everything and zero
        the rest."""
        data = np.ascontiguousarray(data, dtype=np.float32)
        if data.shape != (self.n_traces, self.n_samples):
            raise InvalidDataError(f"data must be {(self.n_traces, self.n_samples)}, got {data.shape}")
        xs, ys = self._window(window)
        krange = None
        if depth_range is not None:
            krange = np.asarray(depth_range)
            if krange.shape != (len(xs), len(ys), 2) or not np.issubdtype(krange.dtype, np.integer):
                raise InvalidDataError(f"depth_range must be ({len(xs)}, {len(ys)}, 2) integers, got "
                                       f"{krange.shape} {krange.dtype}")
            krange = np.ascontiguousarray(np.clip(krange, 0, self.grid.nd), dtype=np.int32)
        run = self._ENGINES[self.engine][0]
        if self.engine == "numba":
            img, fold = run(self, data, xs, ys, with_fold, krange)
        else:
            img, fold = run(self, data, xs, ys, with_fold)
        if with_fold and fold is None:  # the engine does not sum it in the same pass: a second migration
            fold = run(self, np.ones_like(data), xs, ys, False, *([krange] if self.engine == "numba" else []))[0]
        if krange is not None:  # what an engine summed outside the ranges (all but the tiled kernel do) is dropped
            k = np.arange(self.grid.nd)
            outside = (k < krange[..., :1]) | (k >= krange[..., 1:])
            img[outside] = 0.0
            if with_fold:
                fold[outside] = 0.0
        return (img, fold) if with_fold else img

    def _adjoint_numpy_engine(self, data, xs, ys, with_fold):
        return self._adjoint_numpy(data, xs, ys), None

    def _adjoint_numba(self, data, xs, ys, with_fold, krange=None):
        # (image, fold): the fold where the tiled kernel sums it in the same pass, else None
        from gpr3d.migration import _kernels

        shape = (len(xs), len(ys), self.grid.nd)
        img = np.zeros(shape, dtype=np.float32)
        padded = np.zeros((self.n_traces, self.n_samples + 2), dtype=np.float32)
        padded[:, : self.n_samples] = data
        args = list(self._kernel_args(xs, ys))
        path = _kernels.read_path() if self.gather is None else (_kernels.GATHER if self.gather else _kernels.LOADS)
        # only the kernel that runs is built (each is seconds of compilation on a machine's first run): the tiled
        # one where there is an aperture, else the untiled SIMD one; either falls back to the scalar depth loop
        # where the SIMD loop does not build here
        simd_path = path if self.simd else 0
        tiled = simd = None
        if (self.tan_ap > 0 or self.aperture_m is not None) and self.tiled:
            tiled = _kernels.tiled_adjoint(simd_path, with_fold)
            if tiled is None and simd_path:
                simd_path, tiled = 0, _kernels.tiled_adjoint(0, with_fold)
        elif simd_path:
            simd = _kernels.simd_adjoint(path)
            simd_path = path if simd is not None else 0
        if simd_path:
            from gpr3d.migration._simd import W

            nd = self.grid.nd
            # depth and slowness padded to whole SIMD blocks at the top: every column's depth loop ends at the
            # deepest voxel, so the blocks end there too and only the first (at the aperture's start depth) is
            # partly idle (padded at the bottom, a grid of 65 depths paid a whole block for its last voxel); the pad
            # voxels are never live and are discarded
            extra = -nd % W
            args[5] = np.r_[np.full(extra, self.depth[0]), self.depth].astype(np.float32)
            args[6] = np.r_[np.full(extra, self.slow[0]), self.slow].astype(np.float32)
        if tiled is not None:
            # the cost follows the aperture: tiles of columns visit only the traces whose cone reaches them
            mid = (0.5 * (self.tx[:, :2] + self.rx[:, :2])).astype(np.float32)
            reach = self.reach_m
            bsize = max(reach / 2, _kernels.TILE * max(self.grid.dx, self.grid.dy))  # bins of >= one tile
            order, start, bx0, by0, nbx, nby = _kernels.bin_traces(mid, bsize)
            fold = np.zeros(shape if with_fold else (1, 1, 1), dtype=np.float32)
            if krange is None:
                krange = np.zeros(shape[:2] + (2,), np.int32)
                krange[..., 1] = self.grid.nd
            tiled(padded, *args, img, order, start, np.float32(bx0), np.float32(by0), np.float32(bsize), nbx, nby, mid,
                  np.float32(reach), krange, fold)
            return img, (fold if with_fold else None)
        if simd is not None:
            simd(padded, *args, img)
        else:
            _kernels.kernels()[0](padded, *args, img)
        return img, None

    def forward(self, image) -> np.ndarray:
        """Demigration: image ``(nx, ny, nd)`` -> data ``(n_traces, n_samples)`` float32."""
        image = np.ascontiguousarray(image, dtype=np.float32)
        if image.shape != self.grid.shape:
            raise InvalidDataError(f"image must be {self.grid.shape}, got {image.shape}")
        return self._ENGINES[self.engine][1](self, image)

    def _forward_numba(self, image):
        from gpr3d.migration._kernels import kernels

        _, forward = kernels()
        out = np.zeros((self.n_traces, self.n_samples + 2), dtype=np.float32)
        forward(image, *self._kernel_args(), out)
        return np.ascontiguousarray(out[:, : self.n_samples])

    def _adjoint_torch(self, data, xs, ys, with_fold):
        from gpr3d.migration import _torch

        return _torch.adjoint(self, data, xs, ys), None

    def _forward_torch(self, image):
        from gpr3d.migration import _torch

        return _torch.forward(self, image)

    #: engine name -> (adjoint, forward): the numba kernels, the numpy reference, or PyTorch (the GPU path:
    #: ``"torch:cuda"``)
    _ENGINES = {"numba": (_adjoint_numba, _forward_numba), "numpy": (_adjoint_numpy_engine, _forward_numpy),
                "torch": (_adjoint_torch, _forward_torch)}

    def on_grid(self, grid: Grid3D) -> "BackProjection":
        """The same operator (traces, velocity, aperture, weights, kernel choices) on another grid with the same
        depth axis (what coarse-to-fine imaging's coarse pass migrates into)."""
        if (grid.d0, grid.dd, grid.nd) != (self.grid.d0, self.grid.dd, self.grid.nd):
            raise InvalidDataError("on_grid keeps the depth axis: the grid must have the same d0, dd and nd")
        sub = copy.copy(self)
        sub.grid = grid
        sub.x = grid.x.astype(np.float64)
        sub.y = grid.y.astype(np.float64)
        return sub

    def with_traces(self, idx) -> "BackProjection":
        """The same operator (grid, velocity, aperture, weights, kernel choices) for the traces ``idx`` only."""
        sub = copy.copy(self)
        sub.tx = np.ascontiguousarray(self.tx[idx])
        sub.rx = np.ascontiguousarray(self.rx[idx])
        sub.air_gap = np.ascontiguousarray(self.air_gap[idx])
        return sub

    @property
    def reach_m(self) -> float:
        """How far (horizontally, m) from a trace's tx-rx midpoint its aperture reaches at the deepest voxel (inf:
        no aperture)."""
        cone = self.tan_ap * float(self.depth[-1]) + 1e-6 if self.tan_ap > 0 else math.inf
        return min(cone, self.aperture_m + 1e-6) if self.aperture_m is not None else cone

    def _kernel_args(self, xs=None, ys=None):
        f = np.float32
        xs = self.x if xs is None else xs
        ys = self.y if ys is None else ys
        mode = (1 if self.obliquity else 0) | (2 if self.spreading else 0)
        return (self.tx.astype(f), self.rx.astype(f), self.air_gap.astype(f), xs.astype(f), ys.astype(f), self.depth.astype(f),
                self.slow.astype(f), f(self.t0), f(1.0 / self.dt), f(self.n_samples), f(self.tan_ap),
                f(np.finfo(np.float32).max if self.aperture_m is None else self.aperture_m**2), mode)


def dot_test(op: BackProjection, *, seed: int = 0) -> tuple[float, float]:
    """The dot-product test of an operator: ``(<F m, d>, <m, F^H d>)`` for random ``m`` and ``d``, equal (to rounding)
    for an exact adjoint pair.

    Parameters
    ----------
    op : BackProjection
        The operator (``forward`` and ``adjoint``).
    seed : int
        Seeds the random model and data.

    Returns
    -------
    tuple of (float, float)
        The two inner products, in float64.
    """
    rng = np.random.default_rng(seed)
    m = rng.standard_normal(op.grid.shape).astype(np.float32)
    d = rng.standard_normal((op.n_traces, op.n_samples)).astype(np.float32)
    lhs = float(np.sum(op.forward(m).astype(np.float64) * d))
    rhs = float(np.sum(m.astype(np.float64) * op.adjoint(d)))
    return lhs, rhs
