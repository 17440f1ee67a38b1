"""The back projection written once more in PyTorch: the GPU path (CUDA where there is one), the same operator as
the numba kernels and the numpy reference of :class:`~gpr3d.migration.operator.BackProjection` (travel times,
linear interpolation between samples, zero past the record, aperture, obliquity and spreading weights), traces
taken in batches so that a batch's voxels fit in the device's memory. It is chosen with ``engine="torch"`` (the
CPU) or ``"torch:cuda"`` / ``"torch:cuda:N"``; an air gap (rays refracted at the surface) stays with the numba
engine."""

from __future__ import annotations

import math

import numpy as np

from gpr3d.core.deps import require
from gpr3d.core.errors import InvalidDataError

#: voxel-trace pairs held at once (a batch of traces times the columns asked for): about 1 GB of float32
#: intermediates
PAIRS_PER_BATCH = 16_000_000


def check_device(device: str) -> str:
    """The torch device named by ``engine="torch:DEVICE"``, checked: one line when it is not there."""
    torch = require("torch")
    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError):
        raise InvalidDataError(f"engine 'torch:{device}': {device!r} is not a torch device (cpu, cuda, cuda:N)") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise InvalidDataError(f"engine 'torch:{device}': no CUDA device is available here (use 'torch' or 'numba')")
    if dev.type not in ("cpu", "cuda"):
        raise InvalidDataError(f"engine 'torch:{device}': only cpu and cuda devices are supported")
    return str(dev)


def _geometry(op, xs, ys, idx, torch, dev):
    """Sample positions ``u`` (B, nx, ny, nd) and weights ``w`` of the traces ``idx`` over the columns ``xs, ys``:
    float32, as the GPU runs them (the aperture's first depth per column in float64, so that a voxel on the
    cone's edge falls on the side the numba kernels put it)."""
    f32, f64 = torch.float32, torch.float64

    def col(a, k):
        return a[:, k][:, None, None, None]

    X = torch.as_tensor(xs, dtype=f64, device=dev)[None, :, None, None]
    Y = torch.as_tensor(ys, dtype=f64, device=dev)[None, None, :, None]
    tx = torch.as_tensor(op.tx[idx], dtype=f64, device=dev)
    rx = torch.as_tensor(op.rx[idx], dtype=f64, device=dev)
    ha2 = ((X - col(tx, 0)) ** 2 + (Y - col(tx, 1)) ** 2).to(f32)  # (B, nx, ny, 1)
    hb2 = ((X - col(rx, 0)) ** 2 + (Y - col(rx, 1)) ** 2).to(f32)
    D = torch.as_tensor(op.depth, dtype=f32, device=dev)[None, None, None, :]
    za, zb = D + col(tx, 2).to(f32), D + col(rx, 2).to(f32)
    ra, rb = torch.sqrt(ha2 + za ** 2), torch.sqrt(hb2 + zb ** 2)
    slow = torch.as_tensor(op.slow, dtype=f32, device=dev)[None, None, None, :]
    u = (op.t0 + (ra + rb) * slow) / op.dt
    w = torch.ones_like(u)
    if op.obliquity:
        w = w * 0.5 * (za / torch.clamp(ra, min=1e-12) + zb / torch.clamp(rb, min=1e-12))
    if op.spreading:
        w = w * 0.5 * (ra + rb)
    if op.tan_ap > 0 or op.aperture_m is not None:
        hm = torch.sqrt((X - 0.5 * (col(tx, 0) + col(rx, 0))) ** 2 + (Y - 0.5 * (col(tx, 1) + col(rx, 1))) ** 2)
        k = torch.arange(len(op.depth), dtype=f32, device=dev)[None, None, None, :]
        if op.tan_ap > 0:
            kmin = torch.ceil((hm / op.tan_ap - float(op.depth[0])) / op.grid.dd - 1e-12).to(f32)
            w = torch.where(k >= kmin, w, torch.zeros((), dtype=f32, device=dev))
        if op.aperture_m is not None:  # columns beyond the aperture's radius: none of their depths
            w = torch.where(hm <= op.aperture_m, w, torch.zeros((), dtype=f32, device=dev))
    u = torch.clamp(u, 0.0, float(op.n_samples))  # past the end: the zero padding
    return u, w


def _plan(op, xs, ys):
    """Batches of traces, each with the window of columns ``(ix0, ix1, iy0, iy1)`` of ``xs, ys`` its cones reach:
    with an aperture the traces are taken in the order of their midpoints' bins, so that a batch's cones lie
    together and only their columns are computed (a voxel outside every cone of a batch gets nothing from it);
    without one, every batch takes every column."""
    nx, ny, nd = len(xs), len(ys), op.grid.nd
    reach = op.reach_m
    if not math.isfinite(reach):
        step = max(1, PAIRS_PER_BATCH // max(1, nx * ny * nd))
        return [(np.arange(j, min(j + step, op.n_traces)), 0, nx, 0, ny) for j in range(0, op.n_traces, step)]
    mid = 0.5 * (op.tx[:, :2] + op.rx[:, :2])
    b = max(reach, op.grid.dx, op.grid.dy)
    order = np.lexsort((mid[:, 1], np.floor(mid[:, 0] / b)))
    cone = min(nx, int(2 * reach / op.grid.dx) + 2) * min(ny, int(2 * reach / op.grid.dy) + 2)
    step = max(1, PAIRS_PER_BATCH // max(1, cone * nd))
    out, todo = [], [order[j:j + step] for j in range(0, len(order), step)]
    while todo:
        idx = todo.pop()
        lo, hi = mid[idx].min(axis=0) - reach, mid[idx].max(axis=0) + reach
        ix0, ix1 = int(np.searchsorted(xs, lo[0], "left")), int(np.searchsorted(xs, hi[0], "right"))
        iy0, iy1 = int(np.searchsorted(ys, lo[1], "left")), int(np.searchsorted(ys, hi[1], "right"))
        if len(idx) > 1 and len(idx) * (ix1 - ix0) * (iy1 - iy0) * nd > 2 * PAIRS_PER_BATCH:
            todo += [idx[: len(idx) // 2], idx[len(idx) // 2:]]  # spread out: two batches of tighter windows
        elif ix1 > ix0 and iy1 > iy0:
            out.append((idx, ix0, ix1, iy0, iy1))
    return out


def adjoint(op, data, xs, ys) -> np.ndarray:
    """Migration of ``data`` (n_traces, n_samples) onto the columns ``xs, ys`` of ``op``'s grid: (nx, ny, nd)."""
    torch = require("torch")
    dev = torch.device(op.torch_device)
    padded = np.zeros((op.n_traces, op.n_samples + 2), dtype=np.float32)
    padded[:, : op.n_samples] = data
    rows = torch.as_tensor(padded, device=dev)
    img = torch.zeros((len(xs), len(ys), op.grid.nd), dtype=torch.float32, device=dev)
    for idx, ix0, ix1, iy0, iy1 in _plan(op, xs, ys):
        u, w = _geometry(op, xs[ix0:ix1], ys[iy0:iy1], idx, torch, dev)
        i0 = torch.floor(u).to(torch.int64)
        f = u - i0
        r = rows[torch.as_tensor(idx, device=dev)]
        flat = i0.reshape(len(idx), -1)
        a = torch.gather(r, 1, flat).reshape(u.shape)
        b = torch.gather(r, 1, flat + 1).reshape(u.shape)
        img[ix0:ix1, iy0:iy1] += (w * (a + f * (b - a))).sum(dim=0)
    return img.cpu().numpy()


def forward(op, image) -> np.ndarray:
    """Demigration of ``image`` (nx, ny, nd) into data (n_traces, n_samples), the adjoint of :func:`adjoint`."""
    torch = require("torch")
    dev = torch.device(op.torch_device)
    m = torch.as_tensor(np.asarray(image, dtype=np.float32), device=dev)
    out = torch.zeros((op.n_traces, op.n_samples + 2), dtype=torch.float32, device=dev)
    for idx, ix0, ix1, iy0, iy1 in _plan(op, op.x, op.y):
        u, w = _geometry(op, op.x[ix0:ix1], op.y[iy0:iy1], idx, torch, dev)
        i0 = torch.floor(u).to(torch.int64)
        f = u - i0
        val = (w * m[None, ix0:ix1, iy0:iy1]).reshape(len(idx), -1)
        flat, f = i0.reshape(len(idx), -1), f.reshape(len(idx), -1)
        block = torch.zeros((len(idx), op.n_samples + 2), dtype=torch.float32, device=dev)
        block.scatter_add_(1, flat, (1 - f) * val)
        block.scatter_add_(1, flat + 1, f * val)
        out[torch.as_tensor(idx, device=dev)] = block
    return out[:, : op.n_samples].cpu().numpy()
