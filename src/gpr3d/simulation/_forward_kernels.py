"""numba kernels of the fast forward model (private; the physics is in :mod:`gpr3d.simulation.forward`).

Module-level functions with ``cache=True``: numba compiles them once per machine and later processes load them
from its cache (as closures they were compiled again in every process, about 6 s each time on two cores).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from gpr3d.core.raypath import S_AIR, air_ground_time


@njit(cache=True, fastmath=True)
def add_wavelet(out_row, t_arr, amp, dt, wt0, wstep, wvals):
    n = out_row.shape[0]
    nw = wvals.shape[0]
    t_first = t_arr + wt0
    k0 = int(math.ceil(t_first / dt))
    if k0 < 0:
        k0 = 0
    k1 = int((t_first + (nw - 1) * wstep) / dt)
    if k1 > n - 1:
        k1 = n - 1
    for k in range(k0, k1 + 1):
        u = (k * dt - t_first) / wstep
        j = int(u)
        if j < 0 or j >= nw - 1:
            continue
        f = u - j
        out_row[k] += amp * (wvals[j] * (1.0 - f) + wvals[j + 1] * f)


@njit(cache=True, fastmath=True)
def interface_pattern(cos_t, n):
    # |T_TE| of a plane wave leaving the ground (index n) at angle theta, over its value at theta = 0
    sin2 = 1.0 - cos_t * cos_t
    s2 = n * n * sin2
    if s2 < 1.0:
        t = 2.0 * n * cos_t / (n * cos_t + math.sqrt(1.0 - s2))
    else:
        t = 2.0 * n * cos_t / math.sqrt(n * n - 1.0) if n > 1.0 else 0.0
    return t * (n + 1.0) / (2.0 * n)


@njit(cache=True, fastmath=True)
def leg_factor(sx, sy, sz, px, py, pz, n_host, footprint, theta0):
    d = math.sqrt((px - sx) ** 2 + (py - sy) ** 2 + (pz - sz) ** 2)
    if d == 0.0:
        return 1.0
    cos_t = (sz - pz) / d
    if cos_t < 0.0:
        cos_t = 0.0
    f = 1.0
    if footprint == 1:
        f = interface_pattern(cos_t, n_host)
    if theta0 > 0.0:
        th = math.acos(min(cos_t, 1.0))
        f *= math.exp(-0.5 * (th / theta0) ** 2)
    return f


@njit(cache=True, fastmath=True)
def travel(ax, ay, az, bx, by, bz, px, py, pz, gap, v):
    # two-way time tx -> p -> rx: each leg straight through the host, or refracted at the surface when the
    # antennas are held ``gap`` above it (air_ground_time takes both)
    return (air_ground_time(gap, az - pz, math.hypot(ax - px, ay - py), S_AIR, 1.0 / v)
            + air_ground_time(gap, bz - pz, math.hypot(bx - px, by - py), S_AIR, 1.0 / v))


@njit(parallel=True, cache=True, fastmath=True)
def kernel(out, tx, rx, dip, caps, cap_pol, echoes, boxes, box_gamma, layers, v, n_host, alpha, dt, t_src,
           wt0, wstep, wvals, air_amp, ground_amp, spread2d, footprint, theta0, noise, seed, gap):
    n_tr = out.shape[0]
    for i in prange(n_tr):
        row = out[i]
        for k in range(row.shape[0]):
            row[k] = 0.0
        ax, ay, az = tx[i, 0], tx[i, 1], tx[i, 2]
        bx, by, bz = rx[i, 0], rx[i, 1], rx[i, 2]
        h_air = (max(az, 0.0) + max(bz, 0.0)) / 299792458.0  # a bounce above the flat ground
        az = min(az, 0.0)
        bz = min(bz, 0.0)
        mx, my, mz = 0.5 * (ax + bx), 0.5 * (ay + by), 0.5 * (az + bz)
        sep = math.sqrt((ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2)
        if air_amp != 0.0:
            add_wavelet(row, t_src + sep / 299792458.0, air_amp, dt, wt0, wstep, wvals)
        if ground_amp != 0.0:
            add_wavelet(row, t_src + sep / v, ground_amp, dt, wt0, wstep, wvals)
        # capsules: line targets (p0 != p1) and spheres (p0 == p1)
        for c in range(caps.shape[0]):
            p0x, p0y, p0z = caps[c, 0], caps[c, 1], caps[c, 2]
            ux, uy, uz = caps[c, 3] - p0x, caps[c, 4] - p0y, caps[c, 5] - p0z
            r = caps[c, 6]
            L2 = ux * ux + uy * uy + uz * uz
            s = 0.0
            if L2 > 0.0:
                s = ((mx - p0x) * ux + (my - p0y) * uy + (mz - p0z) * uz) / L2
                s = min(max(s, 0.0), 1.0)
            qx, qy, qz = p0x + s * ux, p0y + s * uy, p0z + s * uz
            dx_, dy_, dz_ = mx - qx, my - qy, mz - qz
            dist = math.sqrt(dx_ * dx_ + dy_ * dy_ + dz_ * dz_)
            if dist <= r:
                continue
            px, py, pz = qx + r * dx_ / dist, qy + r * dy_ / dist, qz + r * dz_ / dist
            r1 = math.sqrt((ax - px) ** 2 + (ay - py) ** 2 + (az - pz) ** 2)
            r2 = math.sqrt((bx - px) ** 2 + (by - py) ** 2 + (bz - pz) ** 2)
            path = r1 + r2
            rm = 0.5 * path
            if spread2d:  # everything is a cylinder in 2D
                amp = math.sqrt(0.5 * r) / rm
            elif L2 > 0.0:
                amp = math.sqrt(r / (2.0 * rm)) / (2.0 * rm)
            else:
                amp = r / (2.0 * rm * rm)
            if L2 > 0.0:
                cosphi = (dip[i, 0] * ux + dip[i, 1] * uy + dip[i, 2] * uz) / math.sqrt(L2)
                amp *= max(cosphi * cosphi, cap_pol[c])
            amp *= leg_factor(ax, ay, az, px, py, pz, n_host, footprint, theta0)
            amp *= leg_factor(bx, by, bz, px, py, pz, n_host, footprint, theta0)
            amp *= math.exp(-alpha * path)
            t_arr = t_src + h_air + travel(ax, ay, az, bx, by, bz, px, py, pz, gap, v)
            for e in range(echoes.shape[1]):
                a_e = echoes[c, e, 1]
                if a_e == 0.0:
                    continue
                extra = echoes[c, e, 2]  # equivalent host path of a far-side echo: more spreading
                g = 1.0
                if extra > 0.0:
                    g = rm / (rm + extra)
                    if spread2d:
                        g = math.sqrt(g)
                add_wavelet(row, t_arr + echoes[c, e, 0], amp * a_e * g, dt, wt0, wstep, wvals)
        for b in range(boxes.shape[0]):
            px = min(max(mx, boxes[b, 0]), boxes[b, 3])
            py = min(max(my, boxes[b, 1]), boxes[b, 4])
            pz = min(max(mz, boxes[b, 2]), boxes[b, 5])
            r1 = math.sqrt((ax - px) ** 2 + (ay - py) ** 2 + (az - pz) ** 2)
            r2 = math.sqrt((bx - px) ** 2 + (by - py) ** 2 + (bz - pz) ** 2)
            path = r1 + r2
            if path == 0.0:
                continue
            amp = 1.0 / path if not spread2d else 1.0 / math.sqrt(path)
            amp *= leg_factor(ax, ay, az, px, py, pz, n_host, footprint, theta0)
            amp *= leg_factor(bx, by, bz, px, py, pz, n_host, footprint, theta0)
            amp *= box_gamma[b] * math.exp(-alpha * path)
            add_wavelet(row, t_src + h_air + travel(ax, ay, az, bx, by, bz, px, py, pz, gap, v), amp, dt, wt0, wstep,
                        wvals)
        for ly in range(layers.shape[0]):
            d = layers[ly, 0] + mz  # from the ground under the antenna (z = mz) down to z = -depth
            if d <= 0.0:
                continue
            path = 2.0 * math.sqrt(d * d + 0.25 * sep * sep)
            amp = 1.0 / path if not spread2d else 1.0 / math.sqrt(path)
            amp *= layers[ly, 1] * math.exp(-alpha * path)
            t_l = h_air + 2.0 * air_ground_time(gap, d, 0.5 * sep, S_AIR, 1.0 / v)
            add_wavelet(row, t_src + t_l, amp, dt, wt0, wstep, wvals)
        if noise > 0.0:
            np.random.seed(seed + i)
            for k in range(row.shape[0]):
                row[k] += noise * np.random.standard_normal()
