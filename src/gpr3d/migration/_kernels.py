"""numba kernels of the diffraction-stack operator (private; see operator.py for the maths).

Arithmetic in float32 (16 lanes on AVX-512); traces arrive padded with two zero
samples, so the inner loop needs no bounds branch: times past the end read zeros.

Every kernel is a module-level function with ``cache=True``, so that numba compiles it once per machine and
later processes load it from the cache (closures were recompiled in every process: seconds per command).
"""

from __future__ import annotations

import math
import os
import threading

import numba
import numpy as np
from numba import njit, prange

from gpr3d.core.raypath import S_AIR
from gpr3d.migration import _simd

f32 = np.float32
#: slowness of air, float32 (for antennas held above the ground: ``gap``)
S_AIR32 = f32(S_AIR)
#: Newton steps of the refracted legs: within a 56 deg cone (horizontal reach up to 1.5 x the depth, 2 cm to 1 m of
#: air, eps_r 3-30) three reach Fermat's time to 0.01 ps (gpr3d.core.raypath takes four, for any geometry)
STEPS = 3
W = _simd.W
_CACHE = {}
#: columns per tile side in the tiled adjoint
TILE = 8
#: ``rmax2`` (the squared horizontal radius of the aperture) where there is none: the largest float32, not inf,
#: which fastmath may assume never occurs
NO_RADIUS = f32(np.finfo(np.float32).max)

@njit(fastmath=True, cache=True, inline="always")
def legs(px, py, tx, rx, j):
    # horizontal offsets of a column (px, py) from trace j's transmitter and receiver, and their squares
    ax = px - tx[j, 0]
    ay = py - tx[j, 1]
    bx = px - rx[j, 0]
    by = py - rx[j, 1]
    return ax, ay, bx, by, ax * ax + ay * ay, bx * bx + by * by

@njit(fastmath=True, cache=True, inline="always")
def start_depth(ax, ay, bx, by, tan_ap, rmax2, d0, dd, nd):
    # the first depth index inside the trace's aperture: the cone of half-angle atan(tan_ap) (<= 0: none) about the
    # vertical through the tx-rx midpoint, cut off at the horizontal radius sqrt(rmax2) (NO_RADIUS: none); a column
    # beyond that radius gets nd (no depths)
    hm2 = 0.25 * ((ax + bx) * (ax + bx) + (ay + by) * (ay + by))
    if hm2 > rmax2:
        return nd
    if tan_ap <= 0.0:
        return 0
    k0 = int(math.ceil((math.sqrt(hm2) / tan_ap - d0) / dd - 1e-6))
    return min(max(k0, 0), nd)

@njit(fastmath=True, cache=True, inline="always")
def record_path(slow, off, t0, inv_dt, umax, scap):
    # the square of the longest path (tx -> voxel -> rx, m) whose two-way time still lands inside the record, at the
    # fastest depth's speed or ``scap``, whichever is faster (S_AIR for antennas above the ground, whose rays run
    # partly through air; inf for none), a little longer for float32 rounding; inf when the slowness is not
    # positive, -1 when the record ends before time zero
    smin = min(slow[off], scap)
    for k in range(off + 1, slow.shape[0]):
        smin = min(smin, slow[k])
    if not smin > 0.0:
        return math.inf
    lmax = (float(umax) / float(inv_dt) - float(t0)) / float(smin) * 1.0001
    return lmax * lmax if lmax > 0.0 else -1.0


@njit(fastmath=True, cache=True, inline="always")
def end_depth(ax, ay, bx, by, ha, hb, lmax2, d0, dd, nd):
    # one past the deepest depth index that a trace's record can reach from a column: the two legs are together at
    # least sqrt(|a + b|^2 + (za + zb)^2) long (the triangle inequality, a and b the horizontal legs), and a path
    # longer than sqrt(lmax2) (see record_path) reads the zero padding past the record, which adds exact zeros to
    # the image and to the fold. Cheap when the whole column is in reach (the common case); two indices of margin.
    m2 = (ax + bx) * (ax + bx) + (ay + by) * (ay + by)
    zf = 2.0 * (d0 + (nd - 1) * dd) + ha + hb
    if zf <= 0.0 or m2 + zf * zf < lmax2:
        return nd
    if m2 >= lmax2:
        return 0
    z = 0.5 * (math.sqrt(lmax2 - m2) - ha - hb)
    k1 = int(math.floor((z - d0) / dd)) + 2
    return min(max(k1, 0), nd)


@njit(fastmath=True, cache=True, inline="always")
def sample_position(dk, ha, hb, h2a, h2b, sk, t0, inv_dt, umax):
    # fractional sample index of the two-way time tx -> voxel at depth dk -> rx, clamped to the padded trace;
    # with the vertical legs and path lengths the weights need
    za = dk + ha
    zb = dk + hb
    ra = math.sqrt(h2a + za * za)
    rb = math.sqrt(h2b + zb * zb)
    u = (t0 + (ra + rb) * sk) * inv_dt
    return min(max(u, f32(0.0)), umax), za, zb, ra, rb

@njit(fastmath=True, cache=True, inline="always")
def refracted_leg(h, d, rho, s1, tanc):
    # gpr3d.core.raypath.air_ground_time for h > 0 in float32 without branches (so that the depth loop
    # vectorises): a point at or above the surface (d <= 0) is reached through the air alone, which the ground
    # leg's length then clamped to zero gives; ``tanc``: tan of the critical angle, sin = S_AIR / s1
    d = max(d, f32(0.0))
    qmax = min(rho, d * tanc)
    q = min(rho * d / (h + d), qmax)
    for _ in range(STEPS):
        s = rho - q
        a = math.sqrt(h * h + s * s)
        b = max(math.sqrt(d * d + q * q), f32(1e-30))  # (d = 0: the point on the surface, q = 0 and b = 0)
        grad = s1 * q / b - S_AIR32 * s / a
        # the curvature as (h/a)^2/a + (d/b)^2/b: no cube of a small b to underflow into 0/0 in float32
        curv = S_AIR32 * (h / a) * (h / a) / a + s1 * (d / b) * (d / b) / b
        q = min(max(q - grad / curv, f32(0.0)), qmax)
    s = rho - q
    return S_AIR32 * math.sqrt(h * h + s * s) + s1 * math.sqrt(d * d + q * q)


@njit(fastmath=True, cache=True, inline="always")
def sample_position_air(dk, ha, hb, h2a, h2b, sk, t0, inv_dt, umax, g):
    # as sample_position for antennas held ``g`` above the ground: each leg refracts at the surface
    # (gpr3d.core.raypath); the vertical legs and path lengths for the weights run up to the antennas
    za = dk + ha
    zb = dk + hb
    n = min(S_AIR32 / sk, f32(0.9999999))
    tanc = n / math.sqrt(f32(1.0) - n * n)
    u = (t0 + refracted_leg(g, za, math.sqrt(h2a), sk, tanc) + refracted_leg(g, zb, math.sqrt(h2b), sk, tanc)) * inv_dt
    za += g
    zb += g
    ra = math.sqrt(h2a + za * za)
    rb = math.sqrt(h2b + zb * zb)
    return min(max(u, f32(0.0)), umax), za, zb, ra, rb

@njit(fastmath=True, cache=True, inline="always")
def weight(za, zb, ra, rb, mode):
    # bit 0: obliquity (mean cosine of the two legs), bit 1: spreading (mean leg length)
    w = f32(1.0)
    if mode & 1:
        # (a voxel exactly at an antenna, depth 0 under it, has r = 0: its cosine counts as 0, not 0/0)
        w *= f32(0.5) * (za / max(ra, f32(1e-12)) + zb / max(rb, f32(1e-12)))
    if mode & 2:
        w *= f32(0.5) * (ra + rb)
    return w

@njit(fastmath=True, cache=True, inline="always")
def depth_axis(depth, nd):
    # first real depth and depth step (the aperture's start_depth needs them); the SIMD kernels get ``depth`` padded
    # at the top to whole blocks, so the real depths are its last ``nd``
    off = depth.shape[0] - nd
    return depth[off], (depth[off + 1] - depth[off] if nd > 1 else f32(1.0))

@njit(parallel=True, fastmath=True, cache=True)
def adjoint(data, tx, rx, gap, x, y, depth, slow, t0, inv_dt, umax, tan_ap, rmax2, mode, image):
    # per (column, trace): pass 1 computes the sample positions and weights for all depths
    # (vectorised: two square roots per voxel), pass 2 gathers and accumulates; ``gap`` (per trace): the antennas'
    # height above the ground (> 0: the rays refract at the surface)
    nx, ny, nd = image.shape
    n_tr = data.shape[0]
    d0, dd = depth_axis(depth, nd)
    lmax2 = record_path(slow, 0, t0, inv_dt, umax, math.inf)
    lmax2a = record_path(slow, 0, t0, inv_dt, umax, S_AIR32)
    for c in prange(nx * ny):
        ix = c // ny
        iy = c - ix * ny
        col = image[ix, iy]
        uu = np.empty(nd, np.float32)
        ww = np.ones(nd, np.float32)
        acc = np.zeros(nd, np.float32)
        one = np.uint32(1)
        for j in range(n_tr):
            ax, ay, bx, by, h2a, h2b = legs(x[ix], y[iy], tx, rx, j)
            ha = tx[j, 2]
            hb = rx[j, 2]
            g = gap[j]
            k0 = start_depth(ax, ay, bx, by, tan_ap, rmax2, d0, dd, nd)
            if g > 0:
                k1 = end_depth(ax, ay, bx, by, ha + g, hb + g, lmax2a, d0, dd, nd)
                for k in range(k0, k1):
                    uu[k], za, zb, ra, rb = sample_position_air(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt,
                                                                umax, g)
                    ww[k] = weight(za, zb, ra, rb, mode)
            else:
                k1 = end_depth(ax, ay, bx, by, ha, hb, lmax2, d0, dd, nd)
                if mode == 0:
                    for k in range(k0, k1):
                        uu[k] = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax)[0]
                else:
                    for k in range(k0, k1):
                        uu[k], za, zb, ra, rb = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt,
                                                                umax)
                        ww[k] = weight(za, zb, ra, rb, mode)
            row = data[j]
            # unsigned indices (u >= 0 by the clamp): no negative-index wraparound, so the gathers vectorise
            if mode == 0:
                for k in range(k0, k1):
                    u = uu[k]
                    i0 = np.uint32(u)
                    f = u - f32(i0)
                    acc[k] += row[i0] + f * (row[i0 + one] - row[i0])
            else:
                for k in range(k0, k1):
                    u = uu[k]
                    i0 = np.uint32(u)
                    f = u - f32(i0)
                    acc[k] += ww[k] * (row[i0] + f * (row[i0 + one] - row[i0]))
        for k in range(nd):
            col[k] += acc[k]

@njit(parallel=True, fastmath=True, cache=True)
def forward(image, tx, rx, gap, x, y, depth, slow, t0, inv_dt, umax, tan_ap, rmax2, mode, data):
    nx, ny, nd = image.shape
    n_tr = data.shape[0]
    d0, dd = depth_axis(depth, nd)
    for j in prange(n_tr):
        row = data[j]
        ha = tx[j, 2]
        hb = rx[j, 2]
        g = gap[j]
        for ix in range(nx):
            for iy in range(ny):
                ax, ay, bx, by, h2a, h2b = legs(x[ix], y[iy], tx, rx, j)
                k0 = start_depth(ax, ay, bx, by, tan_ap, rmax2, d0, dd, nd)
                col = image[ix, iy]
                for k in range(k0, nd):
                    if g > 0:
                        u, za, zb, ra, rb = sample_position_air(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt,
                                                                umax, g)
                    else:
                        u, za, zb, ra, rb = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax)
                    i0 = np.uint32(u)
                    f = u - f32(i0)
                    m = weight(za, zb, ra, rb, mode) * col[k]
                    row[i0] += (f32(1.0) - f) * m
                    row[i0 + np.uint32(1)] += f * m


def _after_warmup(group: str) -> None:
    # a background warm-up compiling this group now (gpr3d.core.warmup): wait for it and load the group from the
    # cache, rather than compile it a second time beside it
    from gpr3d.core.warmup import wait

    wait(group)


def kernels():
    """The plain (scalar) adjoint and the forward operator."""
    return adjoint, forward


_S = tuple(_simd.stack(m) for m in range(4))
_SF = tuple(_simd.stack(m, True) for m in range(4))
s0, s1, s2, s3 = _S
sf0, sf1, sf2, sf3 = _SF

#: the SIMD depth loop's ways of reading the trace: one hardware gather, or scalar loads (see :func:`read_path`)
GATHER, LOADS = 1, 2


def read_path() -> int:
    """How the SIMD loop reads the trace here: ``GATHER`` where hardware gathers are fast, ``LOADS`` (scalar
    loads into a vector) on AMD cores (``znver1``..``znver5`` to LLVM): gathers are slow on Zen 1-4, and on Zen 5
    the loads measured 2.88-2.90 s against 2.99-3.07 s for the gathers (the 8000-trace adjoint with its fold).

    ``GPR3D_GATHER=1`` / ``0`` overrides; ``benchmarks/bench_reconstruct.py`` measures both."""
    env = os.environ.get("GPR3D_GATHER", "auto")
    if env in ("0", "1"):
        return GATHER if env == "1" else LOADS
    import llvmlite.binding as llb

    cpu = llb.get_host_cpu_name()
    return LOADS if cpu.startswith("znver") else GATHER


@njit(fastmath=True, cache=True, inline="always")
def _stack(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, mode, fold, path):
    # the explicit-SIMD depth loop for the weights ``mode``, with the fold beside the image where ``fold``, reading
    # the trace by ``path`` (GATHER or LOADS)
    g = path == GATHER
    if fold:
        if mode == 0:
            sf0(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
        elif mode == 1:
            sf1(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
        elif mode == 2:
            sf2(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
        else:
            sf3(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
    elif mode == 0:
        s0(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
    elif mode == 1:
        s1(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
    elif mode == 2:
        s2(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)
    else:
        s3(row, depth, slow, acc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nblk, g)


@njit(parallel=True, fastmath=True, cache=True)
def adjoint_simd(data, tx, rx, gap, x, y, depth, slow, t0, inv_dt, umax, tan_ap, rmax2, mode, image, path):
    # the SIMD depth loop for antennas on the ground; a trace held above it (gap > 0) takes the scalar loop
    nx, ny, nd = image.shape
    n_tr = data.shape[0]
    nblk = depth.shape[0] // W
    off = depth.shape[0] - nd
    d0, dd = depth_axis(depth, nd)
    lmax2 = record_path(slow, off, t0, inv_dt, umax, math.inf)
    lmax2a = record_path(slow, off, t0, inv_dt, umax, S_AIR32)
    none = np.zeros(1, np.float32)
    for c in prange(nx * ny):
        ix = c // ny
        iy = c - ix * ny
        col = image[ix, iy]
        acc = np.zeros(depth.shape[0], np.float32)
        uu = np.empty(nd, np.float32)
        ww = np.empty(nd, np.float32)
        for j in range(n_tr):
            ax, ay, bx, by, h2a, h2b = legs(x[ix], y[iy], tx, rx, j)
            k0 = start_depth(ax, ay, bx, by, tan_ap, rmax2, d0, dd, nd)
            g = gap[j]
            if g > 0:
                k1 = end_depth(ax, ay, bx, by, tx[j, 2] + g, rx[j, 2] + g, lmax2a, d0, dd, nd)
                if k0 < k1:
                    _scalar_depths(data[j], depth[off:], slow[off:], acc[off:], none, h2a, h2b, tx[j, 2], rx[j, 2],
                                   t0, inv_dt, umax, k0, k1, mode, False, uu, ww, g)
                continue
            k1 = end_depth(ax, ay, bx, by, tx[j, 2], rx[j, 2], lmax2, d0, dd, nd)
            if k0 >= k1:
                continue
            _stack(data[j], depth, slow, acc, none, h2a, h2b, tx[j, 2], rx[j, 2], t0, inv_dt, umax, k0 + off,
                   min(nblk, (k1 + off + W - 1) // W), mode, False, path)
        for k in range(nd):
            col[k] += acc[k + off]


def _probe(fn, *extra):
    """``fn`` built and run on a tiny problem (all weight modes), or None where it does not compile here."""
    one = np.zeros((1, 3), f32)
    try:
        for mode in range(4):
            fn(np.zeros((1, 4), f32), one, one, np.zeros(1, f32), np.zeros(1, f32), np.zeros(1, f32), np.arange(W, dtype=f32),
               np.ones(W, f32), f32(0), f32(1), f32(2), f32(0.5), NO_RADIUS, mode,
               np.zeros((1, 1, 2), f32), *extra)
    except Exception:  # noqa: BLE001 - any failure to build means: use the scalar kernel
        return None
    return fn


def simd_adjoint(path: int = GATHER):
    """The adjoint with the explicit-SIMD depth loop of :mod:`._simd` reading the trace by ``path`` (``GATHER`` or
    ``LOADS``), or None where it does not compile.

    Same arguments as the scalar adjoint, except ``depth`` and ``slow`` padded at the top to a
    multiple of ``_simd.W`` (the real depths are the last ``image.shape[2]``).
    """
    key = ("simd", path)
    if key not in _CACHE:
        def run(*args, _path=path):
            return adjoint_simd(*args, _path)

        _CACHE[key] = run if _probe(run) is not None else None
    return _CACHE[key]


@njit(fastmath=True, cache=True, inline="always")
def _scalar_depths(row, depth, slow, acc, facc, h2a, h2b, ha, hb, t0, inv_dt, umax, k0, nd, mode, fold, uu, ww,
                   g):
    # two passes, as in the plain adjoint: the positions and weights (vectorised: square roots in SIMD lanes),
    # then the reads of the trace (scalar loads: no hardware gather, which is slow on some CPUs); ``g``: the
    # antennas' height above the ground (> 0: refracted rays)
    one = np.uint32(1)
    if g > 0:
        for k in range(k0, nd):
            u, za, zb, ra, rb = sample_position_air(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax, g)
            uu[k] = u
            ww[k] = weight(za, zb, ra, rb, mode)
    else:
        for k in range(k0, nd):
            u, za, zb, ra, rb = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax)
            w = weight(za, zb, ra, rb, mode)
            uu[k] = u
            ww[k] = w
    if fold:  # a trace of ones read at u: 1 inside the record, 1 - frac on the last sample, 0 past it
        for k in range(k0, nd):  # (a loop of its own: a branch in the one above would keep it from vectorising)
            facc[k] += ww[k] * min(max(umax - uu[k], f32(0.0)), f32(1.0))
    for k in range(k0, nd):
        u = uu[k]
        i0 = np.uint32(u)
        fr = u - f32(i0)
        acc[k] += ww[k] * (row[i0] + fr * (row[i0 + one] - row[i0]))


@njit(parallel=True, fastmath=True, cache=True)
def adjoint_tiled(data, tx, rx, gap, x, y, depth, slow, t0, inv_dt, umax, tan_ap, rmax2, mode, image,
                  order, bin_start, bx0, by0, bsize, nbx, nby, mid, reach, krange, fold_img, path, fold):
    """The adjoint with an aperture, at a cost that follows the aperture.

    The image is cut into tiles of ``TILE x TILE`` columns, the traces are binned by their tx-rx midpoint (a
    trace index list sorted by bin, ``order``, with each bin's start in ``bin_start``); a tile visits only the
    bins within the aperture's reach (``reach``: the horizontal distance at which the deepest voxel leaves the
    cone) of it, and of their traces only those whose midpoint lies within reach of the tile. Each visited
    trace's row is then read for all the tile's columns while it is in cache, into the tile's accumulators.
    The sum is the same as the plain adjoint's (only voxels outside every aperture are skipped, where that
    adds exact zeros). ``path``: 0 the scalar depth loop, ``GATHER`` or ``LOADS`` the explicit-SIMD one reading the
    trace that way (``depth``, ``slow`` padded at the top to whole blocks).
    ``fold``: the adjoint of a trace of ones is summed into ``fold_img`` in the same pass.
    ``krange`` ``(nx, ny, 2)``: each column's depths ``[lo, hi)`` to sum (the others are left as they are in
    ``image``); a tile whose columns all have none is skipped, and the others look only as far as their deepest
    voxel's cone reaches (a shallow range visits fewer traces). Each summed voxel gets the same terms, in the same
    order, as with every depth.
    """
    nx, ny, nd = image.shape
    d0, dd = depth_axis(depth, nd)
    nblk = depth.shape[0] // W
    off = depth.shape[0] - nd  # top padding of the SIMD blocks (0 for the scalar loop)
    lmax2 = record_path(slow, off, t0, inv_dt, umax, math.inf)
    lmax2a = record_path(slow, off, t0, inv_dt, umax, S_AIR32)
    ntx = (nx + TILE - 1) // TILE
    nty = (ny + TILE - 1) // TILE
    for t in prange(ntx * nty):
        tx0 = (t // nty) * TILE
        ty0 = (t - (t // nty) * nty) * TILE
        tx1 = min(tx0 + TILE, nx)
        ty1 = min(ty0 + TILE, ny)
        xa, xb, ya, yb = x[tx0], x[tx1 - 1], y[ty0], y[ty1 - 1]
        # the deepest voxel any of the tile's columns sums: none, nothing to do; else the reach of its cone
        kmax = 0
        for ix in range(tx0, tx1):
            for iy in range(ty0, ty1):
                if krange[ix, iy, 0] < krange[ix, iy, 1]:
                    kmax = max(kmax, min(krange[ix, iy, 1], nd))
        if kmax == 0:
            continue
        treach = min(reach, tan_ap * depth[off + kmax - 1] + f32(1e-6)) if tan_ap > 0.0 else reach
        acc = np.zeros((TILE * TILE, depth.shape[0]), np.float32)
        facc = np.zeros((TILE * TILE, depth.shape[0] if fold else 1), np.float32)
        uu = np.empty(depth.shape[0], np.float32)
        ww = np.empty(depth.shape[0], np.float32)
        # the tile's columns that sum any depth, listed once: their place, coordinates and depth range
        n_c = 0
        cc = np.empty(TILE * TILE, np.int64)
        cx = np.empty(TILE * TILE, np.float32)
        cy = np.empty(TILE * TILE, np.float32)
        clo = np.empty(TILE * TILE, np.int64)
        chi = np.empty(TILE * TILE, np.int64)
        for ix in range(tx0, tx1):
            for iy in range(ty0, ty1):
                if krange[ix, iy, 0] < krange[ix, iy, 1]:
                    cc[n_c] = (ix - tx0) * TILE + (iy - ty0)
                    cx[n_c] = x[ix]
                    cy[n_c] = y[iy]
                    clo[n_c] = krange[ix, iy, 0]
                    chi[n_c] = krange[ix, iy, 1]
                    n_c += 1
        # per trace, two loops over the listed columns: their legs and depth ranges first (no call, no skip: a
        # tight loop), then the sums of those the trace reaches (the fine pass of coarse-to-fine imaging 25 % and
        # every voxel 12 % faster than one loop doing both: benchmarks/results/bench_stages.md)
        c0 = np.empty(TILE * TILE, np.int64)
        c1 = np.empty(TILE * TILE, np.int64)
        q2a = np.empty(TILE * TILE, np.float32)
        q2b = np.empty(TILE * TILE, np.float32)
        # the bins within reach, one more on each side (float32 rounding at a bin's edge must not drop a trace)
        i_lo = max(int(math.floor((xa - treach - bx0) / bsize)) - 1, 0)
        i_hi = min(int(math.floor((xb + treach - bx0) / bsize)) + 1, nbx - 1)
        j_lo = max(int(math.floor((ya - treach - by0) / bsize)) - 1, 0)
        j_hi = min(int(math.floor((yb + treach - by0) / bsize)) + 1, nby - 1)
        r2 = treach * treach
        for bi in range(i_lo, i_hi + 1):
            for bj in range(j_lo, j_hi + 1):
                b = bi * nby + bj
                for q in range(bin_start[b], bin_start[b + 1]):
                    j = order[q]
                    # the midpoint's distance to the tile's rectangle: beyond reach, no column sees the trace
                    ex = max(xa - mid[j, 0], f32(0.0), mid[j, 0] - xb)
                    ey = max(ya - mid[j, 1], f32(0.0), mid[j, 1] - yb)
                    if ex * ex + ey * ey > r2:
                        continue
                    row = data[j]
                    ha = tx[j, 2]
                    hb = rx[j, 2]
                    g = gap[j]
                    if g > 0:
                        la, lb, l2 = ha + g, hb + g, lmax2a
                    else:
                        la, lb, l2 = ha, hb, lmax2
                    for i in range(n_c):
                        ax, ay, bx, by, h2a, h2b = legs(cx[i], cy[i], tx, rx, j)
                        c0[i] = max(start_depth(ax, ay, bx, by, tan_ap, rmax2, d0, dd, nd), clo[i])
                        c1[i] = min(end_depth(ax, ay, bx, by, la, lb, l2, d0, dd, nd), chi[i])
                        q2a[i] = h2a
                        q2b[i] = h2b
                    for i in range(n_c):
                        k0 = c0[i]
                        k1 = c1[i]
                        if k0 < k1:
                            c = cc[i]
                            if path and g <= 0:
                                _stack(row, depth, slow, acc[c], facc[c], q2a[i], q2b[i], ha, hb, t0, inv_dt, umax,
                                       k0 + off, min(nblk, (k1 + off + W - 1) // W), mode, fold, path)
                            else:
                                _scalar_depths(row, depth[off:], slow[off:], acc[c, off:],
                                               facc[c, off:] if fold else facc[c], q2a[i], q2b[i], ha, hb, t0,
                                               inv_dt, umax, k0, k1, mode, fold, uu, ww, g)
        for ix in range(tx0, tx1):
            for iy in range(ty0, ty1):
                c = (ix - tx0) * TILE + (iy - ty0)
                col = image[ix, iy]
                klo = max(krange[ix, iy, 0], 0)
                khi = min(krange[ix, iy, 1], nd)
                for k in range(klo, khi):
                    col[k] += acc[c, k + off]
                if fold:
                    fcol = fold_img[ix, iy]
                    for k in range(klo, khi):
                        fcol[k] += facc[c, k + off]


def tiled_adjoint(path: int, fold: bool = False):
    """:func:`adjoint_tiled` with its flags bound (``path``: 0 for the scalar depth loop, ``GATHER`` or ``LOADS``
    for the SIMD one), or None where it does not build."""
    key = ("tiled", path, fold)
    with _TILED_LOCK:  # (one thread builds and probes it: see preload_tiled)
        if key not in _CACHE:
            _CACHE[key] = _built_tiled(path, fold)
    return _CACHE[key]


def _built_tiled(path: int, fold: bool):
    # the tiled adjoint with its flags bound, once it has built and run on a tiny problem; None where it does not
    _after_warmup("tiled")

    def run(*args, _path=path, _fold=fold):
        return adjoint_tiled(*args, _path, _fold)

    extra = (np.zeros(0, np.int64), np.zeros(2, np.int64), f32(0), f32(0), f32(1), 1, 1, np.zeros((1, 2), f32),
             f32(1), np.array([[[0, 2]]], np.int32), np.zeros((1, 1, 2), f32))
    return run if _probe(run, *extra) is not None else None


#: held while the tiled adjoint is built or loaded and probed: a second thread asking for it waits, then finds it
#: in ``_CACHE`` (no two threads run its probe at once: numba's workqueue threading layer aborts on that)
_TILED_LOCK = threading.Lock()


def preload_tiled(path: int | None = None, fold: bool = True) -> threading.Thread | None:
    """Load the tiled adjoint (``tiled_adjoint(path, fold)``; ``path`` None: :func:`read_path`'s) from numba's
    cache in a background thread, and return the thread (started); None, and nothing done, where the kernel is not
    known to be compiled (no background warm-up has recorded it, :mod:`gpr3d.core.warmup`: the first command builds
    it as before, waiting for the warm-up in a timed stage of its own).

    A command that will migrate starts this before it reads its input: the load (about 0.3 s on two cores) then
    runs while the file is read, and the migration finds the kernel ready, or waits for the thread to finish it.

    Parameters
    ----------
    path : int, optional
        How the SIMD loop reads the trace (``GATHER``, ``LOADS``; 0: the scalar loop); default this CPU's.
    fold : bool
        The kernel that sums the fold beside the image (``reconstruct``'s).

    Returns
    -------
    threading.Thread or None
        The loading thread, started (a daemon), or None where nothing was preloaded.
    """
    from gpr3d.core import warmup

    if "tiled" not in warmup.done():
        return None
    t = threading.Thread(target=tiled_adjoint, args=(read_path() if path is None else path, fold), daemon=True,
                         name="gpr3d-preload-tiled")
    t.start()
    return t


def bin_traces(mid: np.ndarray, bsize: float):
    """Traces binned by their midpoints ``mid`` (n, 2) on a square grid of side ``bsize``: the trace order sorted by
    bin (stable: by trace within a bin), each bin's start in that order (``nbx * nby + 1``), the grid's origin and
    size. A trace's bin is ``(mid - origin) // bsize`` along each axis (Python's floor division, also for the
    grid's extent), numbered ``i * nby + j``.

    The bins' origin is a whole multiple of ``bsize``, so that any subset of the traces (a site tile's) falls into
    the same bins, visited in the same order: the sums, and so the image, come out bit for bit the same."""
    bx0 = math.floor(float(mid[:, 0].min()) / bsize) * bsize
    by0 = math.floor(float(mid[:, 1].min()) / bsize) * bsize
    nbx = int((mid[:, 0].max() - bx0) // bsize) + 1
    nby = int((mid[:, 1].max() - by0) // bsize) + 1
    bi = np.clip(((mid[:, 0] - bx0) // bsize).astype(np.int64), 0, nbx - 1)
    bj = np.clip(((mid[:, 1] - by0) // bsize).astype(np.int64), 0, nby - 1)
    b = bi * nby + bj
    order = np.argsort(b, kind="stable").astype(np.int64)
    start = np.searchsorted(b[order], np.arange(nbx * nby + 1)).astype(np.int64)
    return order, start, bx0, by0, nbx, nby
