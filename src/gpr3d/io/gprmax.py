"""gprMax output files: single A-scans and merged B-scans (gprMax 4 ``.h5``, gprMax 3 ``.out``).

Both versions write HDF5 with root attributes ``gprMax`` (version), ``Iterations``,
``dt``, ``dx_dy_dz``, ``srcsteps``, ``rxsteps`` and one group per receiver
``rxs/rxN`` holding field components (``Ex`` ... ``Hz``) of shape ``(iterations,)``
or, once merged, ``(iterations, n_traces)``. gprMax 4's merge tool also writes
``trace_metadata/{srcs,rxs}/.../Position`` with the real position of every trace;
without it positions follow from the step attributes. gprMax 3's merge tool keeps only ``Iterations``, ``dt``,
``nrx`` and ``rxs/rxN/<component>`` (no ``gprMax`` attribute, no geometry): such files are recognised by that
structure and read with no positions (a Survey without ``positions_xyz``; give them, e.g. as poses).

Frames: gprMax models put the vertical on their y axis (as in its B-scan
examples), so a gprMax point ``(x, y, z)`` is the world point ``(x, -z, y)``
(right-handed, z up). Each receiver becomes one Survey; the antenna midpoint
and the tx-rx offset come from the source and receiver positions.
"""

from __future__ import annotations

import math

import h5py
import numpy as np

from gpr3d.core.errors import FormatError
from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.survey import Survey
from gpr3d.io._common import check_file, check_hdf5_survives, hdf5_errors, header_count

__all__ = ["is_gprmax", "read_gprmax", "read_gprmax_waveform", "gprmax_to_world", "COMPONENTS"]

COMPONENTS = ("Ex", "Ey", "Ez", "Hx", "Hy", "Hz", "Ix", "Iy", "Iz")
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def gprmax_to_world(points: np.ndarray) -> np.ndarray:
    """gprMax model coordinates ``(..., 3)`` to world coordinates (z up)."""
    p = np.asarray(points, dtype=float)
    return np.stack([p[..., 0], 0.0 - p[..., 2], p[..., 1]], axis=-1) + 0.0


def _is_hdf5(path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(8) == HDF5_SIGNATURE
    except OSError:
        return False


def _has_gprmax_layout(f) -> bool:
    """gprMax's structure: root attributes ``Iterations`` and ``dt``, and a group ``rxs`` of receiver groups holding
    field components. gprMax 3's merge tool writes just that (with ``nrx``), without the ``gprMax`` attribute."""
    if "Iterations" not in f.attrs or "dt" not in f.attrs or not isinstance(f.get("rxs"), h5py.Group):
        return False
    return any(isinstance(g, h5py.Group) and any(c in g for c in COMPONENTS) for g in f["rxs"].values())


def is_gprmax(path) -> bool:
    if not _is_hdf5(path):
        return False
    try:
        with h5py.File(path, "r") as f:
            return ("gprMax" in f.attrs and "rxs" in f) or _has_gprmax_layout(f)
    except Exception:  # noqa: BLE001 - detection never raises
        return False


def _attr_vec(f, name, default=(0, 0, 0)):
    v = f.attrs.get(name)
    return np.asarray(default if v is None else v, dtype=float).reshape(3)


def read_gprmax_waveform(path, source: str = "src1"):
    """The excitation of ``source`` in a gprMax 4 output: ``(times_s, samples)`` or None if absent."""
    p = check_file(path)
    with h5py.File(p, "r") as f:
        key = f"srcs/{source}/excitation/samples"
        if key not in f:
            return None
        samples = np.asarray(f[key][()], dtype=float)
        ex = f[f"srcs/{source}/excitation"]
        dt = float(ex.attrs.get("SampleInterval", f.attrs["dt"]))
        offset = float(ex.attrs.get("TimeSampleOffset", 0.0))
    return offset + np.arange(samples.size) * dt, samples


def read_gprmax(path, *, component: str = "Ez") -> list[Survey]:
    """Read every receiver of a gprMax output as a :class:`~gpr3d.core.survey.Survey` of ``component``.

    Parameters
    ----------
    path : a gprMax ``.h5`` (v4) or ``.out`` (v3) file, single trace or merged.
    component : field component to read (``Ex`` .. ``Hz``); ``Ez`` is what 2D TM
        B-scans record.
    """
    p = check_file(path)
    if component not in COMPONENTS:
        raise FormatError(p, f"unknown field component {component!r}; choose from {', '.join(COMPONENTS)}")
    if not _is_hdf5(p):
        raise FormatError(p, "not an HDF5 file, so not a gprMax output")
    check_hdf5_survives(p)
    with hdf5_errors(p):
        return _read_gprmax(p, component)


def _read_gprmax(p, component):
    with h5py.File(p, "r") as f:
        if "gprMax" in f.attrs:
            version = f.attrs["gprMax"]
            version = version.decode() if isinstance(version, bytes) else str(version)
        elif _has_gprmax_layout(f):  # gprMax 3's merge tool keeps only Iterations, dt, nrx and rxs/rxN/<component>
            version = "unknown (merged file without a gprMax attribute)"
        else:
            raise FormatError(p, "HDF5 file has neither a 'gprMax' attribute nor gprMax's layout (Iterations, dt and "
                                 "rxs/rxN/<component>): not a gprMax output")
        try:
            dt = float(f.attrs["dt"])
            iterations = f.attrs["Iterations"]
        except (KeyError, TypeError, ValueError):
            raise FormatError(p, "gprMax output lacks the 'dt' or 'Iterations' attribute") from None
        iterations = header_count(p, "Iterations", iterations, lo=2, hi=10**9)
        if not (math.isfinite(dt) and dt > 0):
            raise FormatError(p, f"gprMax dt = {dt!r} is not a positive number")
        dl = _attr_vec(f, "dx_dy_dz", (1, 1, 1))
        srcsteps = _attr_vec(f, "srcsteps") * dl
        rxsteps = _attr_vec(f, "rxsteps") * dl
        if "rxs" not in f or len(f["rxs"]) == 0:
            raise FormatError(p, "gprMax output holds no receivers")
        rx_names = sorted(f["rxs"], key=lambda s: int("".join(c for c in s if c.isdigit()) or 0))
        src_pos = None
        src_group = None
        if "srcs" in f and len(f["srcs"]):
            src_group = sorted(f["srcs"])[0]
            sp = f["srcs"][src_group].attrs.get("Position")
            src_pos = None if sp is None else np.asarray(sp, dtype=float)
        waveform = {}
        if src_group is not None and "excitation" in f["srcs"][src_group]:
            ex = f["srcs"][src_group]["excitation"].attrs
            for k in ("WaveformType", "WaveformFrequency", "WaveformAmplitude", "SourceType"):
                if k in ex:
                    v = ex[k]
                    waveform[k] = v.decode() if isinstance(v, bytes) else (v.item() if hasattr(v, "item") else v)
        tm = f.get("trace_metadata")
        if src_group is None and tm is not None and "srcs" in tm and len(tm["srcs"]):
            src_group = sorted(tm["srcs"])[0]
        surveys = []
        for ch, name in enumerate(rx_names):
            g = f["rxs"][name]
            if component not in g:
                have = ", ".join(k for k in g if k in COMPONENTS)
                raise FormatError(p, f"receiver {name} has no {component} output (has {have or 'none'})")
            arr = np.asarray(g[component][()])
            if arr.ndim == 1:
                arr = arr[:, None]
            if arr.ndim != 2 or arr.shape[0] != iterations:
                raise FormatError(p, f"{name}/{component} has shape {arr.shape}, expected ({iterations}, n_traces)")
            n_tr = arr.shape[1]
            data = np.ascontiguousarray(arr.T, dtype=np.float32)
            bad = np.count_nonzero(~np.isfinite(data))
            if bad:
                raise FormatError(p, f"{name}/{component} holds {bad} NaN/inf samples (the simulation went unstable?)")
            idx = np.arange(n_tr)[:, None]
            if tm is not None and f"rxs/{name}/Position" in tm:
                rx = np.asarray(tm[f"rxs/{name}/Position"][()], dtype=float)
                pos_source = "gprMax trace_metadata"
            elif "Position" in g.attrs or np.any(rxsteps != 0):
                rx0 = np.asarray(g.attrs.get("Position", (0, 0, 0)), dtype=float)
                rx = rx0[None, :] + idx * rxsteps[None, :]
                pos_source = "gprMax receiver position + rxsteps"
            else:  # a merged file that kept no geometry: positions are unknown, not all at the origin
                rx = None
                pos_source = "none in the file (give the trace positions)"
            if tm is not None and src_group is not None and f"srcs/{src_group}/Position" in tm:
                tx = np.asarray(tm[f"srcs/{src_group}/Position"][()], dtype=float)
            elif src_pos is not None:
                tx = src_pos[None, :] + idx * srcsteps[None, :]
            else:
                tx = None if rx is None else rx.copy()
            mid, orient, offset = None, None, 0.0
            if rx is not None:
                if tx is None or rx.shape != (n_tr, 3) or tx.shape != (n_tr, 3):
                    raise FormatError(p, "trace_metadata positions do not match the number of traces")
                tx_w, rx_w = gprmax_to_world(tx), gprmax_to_world(rx)
                mid = (tx_w + rx_w) / 2
                sep = rx_w - tx_w
                offset = float(np.median(np.linalg.norm(sep, axis=1)))
                if offset > 0:
                    orient = quat_from_yaw(np.arctan2(sep[:, 1], sep[:, 0]))
            freq = waveform.get("WaveformFrequency")
            surveys.append(
                Survey(
                    data=data,
                    dt_s=dt,
                    positions_xyz=mid,
                    orientations_quat_wxyz=orient,
                    offset_m=offset,
                    frequency_hz=float(freq) if freq else None,
                    metadata={
                        "format": "gprmax",
                        "path": str(p),
                        "channel": ch,
                        "n_channels": len(rx_names),
                        "receiver": name,
                        "component": component,
                        "gprmax_version": version,
                        "title": str(f.attrs.get("Title", "")),
                        "dx_dy_dz": dl.tolist(),
                        "merged": bool(arr.shape[1] > 1 or "ntraces" in f.attrs),
                        "positions_source": pos_source,
                        "tx_positions_gprmax": tx.tolist() if tx is not None and n_tr <= 4096 else None,
                        "waveform": waveform or None,
                        "antenna": f"gprMax {waveform.get('SourceType', 'source')}" if waveform else "gprMax",
                    },
                )
            )
    return surveys
