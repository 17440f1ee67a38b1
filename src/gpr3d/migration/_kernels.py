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
    if _CACHE:
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

    @njit(parallel=True, fastmath=True, cache=True)
    def adjoint(data, tx, rx, x, y, depth, slow, t0, inv_dt, umax, tan_ap, mode, image):
        # per (column, trace): pass 1 computes the sample positions and weights for all depths
        # (vectorised: two square roots per voxel), pass 2 gathers and accumulates
        nx, ny, nd = image.shape
        n_tr = data.shape[0]
        d0 = depth[0]
        dd = depth[1] - depth[0] if nd > 1 else f32(1.0)
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
                        za = depth[k] + ha
                        zb = depth[k] + hb
                        u = (t0 + (math.sqrt(h2a + za * za) + math.sqrt(h2b + zb * zb)) * slow[k]) * inv_dt
                        uu[k] = min(max(u, f32(0.0)), umax)
                else:
                    for k in range(k0, nd):
                        za = depth[k] + ha
                        zb = depth[k] + hb
                        ra = math.sqrt(h2a + za * za)
                        rb = math.sqrt(h2b + zb * zb)
                        u = (t0 + (ra + rb) * slow[k]) * inv_dt
                        uu[k] = min(max(u, f32(0.0)), umax)
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
    def adjoint_surface(data, tx, rx, x, y, depth, slow, t0, inv_dt, umax, image):
        # the common case, kept lean: antennas on the surface, no aperture, no weights
        nx, ny, nd = image.shape
        n_tr = data.shape[0]
        z2 = depth * depth
        one = np.uint32(1)
        for c in prange(nx * ny):
            ix = c // ny
            iy = c - ix * ny
            col = image[ix, iy]
            uu = np.empty(nd, np.float32)
            acc = np.zeros(nd, np.float32)
            for j in range(n_tr):
                _, _, _, _, h2a, h2b = legs(x[ix], y[iy], tx, rx, j)
                for k in range(nd):
                    u = (t0 + (math.sqrt(h2a + z2[k]) + math.sqrt(h2b + z2[k])) * slow[k]) * inv_dt
                    uu[k] = min(max(u, f32(0.0)), umax)
                row = data[j]
                for k in range(nd):
                    u = uu[k]
                    i0 = np.uint32(u)
                    f = u - f32(i0)
                    acc[k] += row[i0] + f * (row[i0 + one] - row[i0])
            for k in range(nd):
                col[k] += acc[k]

    @njit(parallel=True, fastmath=True, cache=True)
    def forward(image, tx, rx, x, y, depth, slow, t0, inv_dt, umax, tan_ap, mode, data):
        nx, ny, nd = image.shape
        n_tr = data.shape[0]
        d0 = depth[0]
        dd = depth[1] - depth[0] if nd > 1 else f32(1.0)
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
                        za = depth[k] + ha
                        zb = depth[k] + hb
                        ra = math.sqrt(h2a + za * za)
                        rb = math.sqrt(h2b + zb * zb)
                        u = (t0 + (ra + rb) * slow[k]) * inv_dt
                        u = min(max(u, f32(0.0)), umax)
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

    _CACHE["adjoint"], _CACHE["forward"], _CACHE["adjoint_surface"] = adjoint, forward, adjoint_surface
    return adjoint, forward


def adjoint_surface_kernel():
    """The lean adjoint for antennas on the surface with no aperture and no weights."""
    kernels()
    return _CACHE["adjoint_surface"]
