"""numba kernels of the diffraction-stack operator (private; see operator.py for the maths).

Arithmetic in float32 (16 lanes on AVX-512); traces arrive padded with two zero
samples, so the inner loop needs no bounds branch: times past the end read zeros.
"""

from __future__ import annotations

import math

import numpy as np

from gpr3d.core.deps import require

_CACHE = {}


def kernels():
    if "adjoint" in _CACHE:
        return _CACHE["adjoint"], _CACHE["forward"]
    numba = require("numba")
    njit, prange = numba.njit, numba.prange
    f32 = np.float32

    @njit(fastmath=True, cache=True, inline="always")
    def legs(px, py, tx, rx, j):
        # horizontal offsets of a column (px, py) from trace j's transmitter and receiver, and their squares
        ax = px - tx[j, 0]
        ay = py - tx[j, 1]
        bx = px - rx[j, 0]
        by = py - rx[j, 1]
        return ax, ay, bx, by, ax * ax + ay * ay, bx * bx + by * by

    @njit(fastmath=True, cache=True, inline="always")
    def start_depth(ax, ay, bx, by, tan_ap, d0, dd, nd):
        if tan_ap <= 0.0:
            return 0
        hm = math.sqrt(0.25 * ((ax + bx) * (ax + bx) + (ay + by) * (ay + by)))
        k0 = int(math.ceil((hm / tan_ap - d0) / dd - 1e-6))
        return min(max(k0, 0), nd)

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
    def depth_axis(depth, nd):
        # first depth and depth step (the aperture's start_depth needs them)
        return depth[0], (depth[1] - depth[0] if nd > 1 else f32(1.0))

    @njit(parallel=True, fastmath=True, cache=True)
    def adjoint(data, tx, rx, x, y, depth, slow, t0, inv_dt, umax, tan_ap, mode, image):
        # per (column, trace): pass 1 computes the sample positions and weights for all depths
        # (vectorised: two square roots per voxel), pass 2 gathers and accumulates
        nx, ny, nd = image.shape
        n_tr = data.shape[0]
        d0, dd = depth_axis(depth, nd)
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
                k0 = start_depth(ax, ay, bx, by, tan_ap, d0, dd, nd)
                if mode == 0:
                    for k in range(k0, nd):
                        uu[k] = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax)[0]
                else:
                    for k in range(k0, nd):
                        uu[k], za, zb, ra, rb = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax)
                        w = f32(1.0)
                        if mode & 1:
                            w *= f32(0.5) * (za / ra + zb / rb)
                        if mode & 2:
                            w *= f32(0.5) * (ra + rb)
                        ww[k] = w
                row = data[j]
                # unsigned indices (u >= 0 by the clamp): no negative-index wraparound, so the gathers vectorise
                if mode == 0:
                    for k in range(k0, nd):
                        u = uu[k]
                        i0 = np.uint32(u)
                        f = u - f32(i0)
                        acc[k] += row[i0] + f * (row[i0 + one] - row[i0])
                else:
                    for k in range(k0, nd):
                        u = uu[k]
                        i0 = np.uint32(u)
                        f = u - f32(i0)
                        acc[k] += ww[k] * (row[i0] + f * (row[i0 + one] - row[i0]))
            for k in range(nd):
                col[k] += acc[k]

    @njit(parallel=True, fastmath=True, cache=True)
    def forward(image, tx, rx, x, y, depth, slow, t0, inv_dt, umax, tan_ap, mode, data):
        nx, ny, nd = image.shape
        n_tr = data.shape[0]
        d0, dd = depth_axis(depth, nd)
        for j in prange(n_tr):
            row = data[j]
            ha = tx[j, 2]
            hb = rx[j, 2]
            for ix in range(nx):
                for iy in range(ny):
                    ax, ay, bx, by, h2a, h2b = legs(x[ix], y[iy], tx, rx, j)
                    k0 = start_depth(ax, ay, bx, by, tan_ap, d0, dd, nd)
                    col = image[ix, iy]
                    for k in range(k0, nd):
                        u, za, zb, ra, rb = sample_position(depth[k], ha, hb, h2a, h2b, slow[k], t0, inv_dt, umax)
                        i0 = np.uint32(u)
                        f = u - f32(i0)
                        w = f32(1.0)
                        if mode & 1:
                            w *= f32(0.5) * (za / ra + zb / rb)
                        if mode & 2:
                            w *= f32(0.5) * (ra + rb)
                        m = w * col[k]
                        row[i0] += (f32(1.0) - f) * m
                        row[i0 + np.uint32(1)] += f * m

    _CACHE["adjoint"], _CACHE["forward"] = adjoint, forward
    _CACHE["helpers"] = legs, start_depth, depth_axis
    return adjoint, forward


def simd_adjoint():
    """The adjoint with the explicit-SIMD depth loop of :mod:`._simd`, or None where it does not compile.

    Same arguments as the scalar adjoint, except ``depth`` and ``slow`` padded to a
    multiple of ``_simd.W`` (the real depth count is ``image.shape[2]``).
    """
    if "simd" in _CACHE:
        return _CACHE["simd"]
    numba = require("numba")
    from gpr3d.migration import _simd

    kernels()
    legs, start_depth, depth_axis = _CACHE["helpers"]
    s0, s1, s2, s3 = (_simd.stack(m) for m in range(4))
    W = _simd.W

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def adjoint_simd(data, tx, rx, x, y, depth, slow, t0, inv_dt, umax, tan_ap, mode, image):
        nx, ny, nd = image.shape
        n_tr = data.shape[0]
        nblk = depth.shape[0] // W
        d0, dd = depth_axis(depth, nd)
        for c in numba.prange(nx * ny):
            ix = c // ny
            iy = c - ix * ny
            col = image[ix, iy]
            acc = np.zeros(depth.shape[0], np.float32)
            for j in range(n_tr):
                ax, ay, bx, by, h2a, h2b = legs(x[ix], y[iy], tx, rx, j)
                k0 = start_depth(ax, ay, bx, by, tan_ap, d0, dd, nd)
                if k0 >= nd:
                    continue
                args = (data[j], depth, slow, acc, h2a, h2b, tx[j, 2], rx[j, 2], t0, inv_dt, umax, k0, nblk)
                if mode == 0:
                    s0(*args)
                elif mode == 1:
                    s1(*args)
                elif mode == 2:
                    s2(*args)
                else:
                    s3(*args)
            for k in range(nd):
                col[k] += acc[k]

    try:  # compile now, on a tiny problem, so that a CPU/LLVM without support falls back cleanly
        f = np.float32
        one = np.zeros((1, 3), f)
        for mode in range(4):
            adjoint_simd(np.zeros((1, 4), f), one, one, np.zeros(1, f), np.zeros(1, f), np.arange(W, dtype=f),
                         np.ones(W, f), f(0), f(1), f(2), f(0), mode, np.zeros((1, 1, 2), f))
    except Exception:  # noqa: BLE001 - any failure to build means: use the scalar kernel
        adjoint_simd = None
    _CACHE["simd"] = adjoint_simd
    return adjoint_simd
