"""The :class:`Survey`: one channel of GPR traces with everything needed to place them.

A survey holds a B-scan ``data`` of shape ``(n_traces, n_samples)`` (float32), its
sample interval ``dt_s`` (s), time zero ``t0_s`` (s from the first sample), and,
optionally, per-trace timestamps and antenna poses (``world_from_antenna``:
``positions_xyz`` in metres, ``orientations_quat_wxyz``). Metadata keeps what the
source file said; ``history`` records every processing step with its arguments.

Processing methods return a new Survey and never modify the one they are called on::

    >>> import gpr3d
    >>> s = gpr3d.read("FILE____032.DZT")                         # doctest: +SKIP
    >>> p = s.time_zero().dewow().remove_background().gain_sec(alpha_per_s=5e7)  # doctest: +SKIP
    >>> [h["step"] for h in p.history]                             # doctest: +SKIP
    ['time_zero', 'dewow', 'remove_background', 'gain_sec']
"""

from __future__ import annotations

import copy as _copy
import datetime as _dt
import importlib
import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.core.jsonutil import jsonable as _jsonable
from gpr3d.core.poses import normalize_quat, quat_from_yaw, yaw_from_quat
from gpr3d.core.units import twt_to_depth

__all__ = ["Survey", "register_plugin", "PLUGINS"]

#: What :meth:`Survey.save`, :meth:`Survey.load` and :meth:`Survey.apply` call, by role: ``"save"``
#: ``(survey, path)``, ``"load"`` ``(path) -> Survey`` and ``"step"`` ``(survey, name, **kwargs) -> Survey``. The
#: packages above ``core`` fill it (``gpr3d/__init__.py``: HDF5 from :mod:`gpr3d.io.hdf5`, the steps of
#: :mod:`gpr3d.processing.steps`), so the data model needs neither; each entry is a callable or a
#: ``"module:function"`` name imported on first use (as entry points are), which keeps ``import gpr3d`` light.
PLUGINS: dict = {}
_ROLES = ("save", "load", "step")


def register_plugin(role: str, func) -> None:
    """Name what a :class:`Survey` method calls for ``role`` (one of ``"save"``, ``"load"``, ``"step"``).

    Parameters
    ----------
    role : str
        ``"save"``, ``"load"`` or ``"step"`` (see :data:`PLUGINS`).
    func : callable or str
        The function, or its ``"package.module:function"`` name, imported when first called.

    Raises
    ------
    ValueError
        For another role, or a name without ``":"``.
    """
    if role not in _ROLES:
        raise ValueError(f"unknown Survey plug-in role {role!r}; known: {', '.join(_ROLES)}")
    if isinstance(func, str) and func.count(":") != 1:
        raise ValueError(f"plug-in {func!r}: name it 'package.module:function'")
    PLUGINS[role] = func


def _plugin(role: str):
    func = PLUGINS.get(role)
    if func is None:
        raise GPR3DError(f"no Survey {role!r} plug-in is registered (gpr3d registers its own on import)")
    if isinstance(func, str):
        module, name = func.split(":")
        func = PLUGINS[role] = getattr(importlib.import_module(module), name)
    return func

_PER_TRACE = ("timestamps_s", "positions_xyz", "orientations_quat_wxyz")


def _optional_float(name: str, value, *, positive: bool = False, minimum: float | None = None):
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InvalidDataError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise InvalidDataError(f"{name} must be finite, got {v}")
    if positive and v <= 0:
        raise InvalidDataError(f"{name} must be > 0, got {v}")
    if minimum is not None and v < minimum:
        raise InvalidDataError(f"{name} must be >= {minimum}, got {v}")
    return v


@dataclass(eq=False, repr=False)
class Survey:
    """One channel of GPR traces.

    Parameters
    ----------
    data : array (n_traces, n_samples)
        Trace amplitudes; stored as C-contiguous float32.
    dt_s : float
        Sample interval (s).
    t0_s : float
        Time zero (s after the first sample): when the wave leaves the surface.
    timestamps_s : array (n_traces,), optional
        Acquisition time of each trace (s; any epoch, monotonic within a survey).
    positions_xyz : array (n_traces, 3), optional
        Antenna midpoint in the world frame (m, z up).
    orientations_quat_wxyz : array (n_traces, 4), optional
        ``world_from_antenna`` rotation of each trace; antenna x is the heading.
    offset_m : float
        Transmitter-receiver separation (m).
    frequency_hz : float, optional
        Nominal centre frequency of the antenna (Hz).
    eps_r : float, optional
        Relative permittivity hint for the host medium (e.g. from the file header).
    metadata : dict
        JSON-serialisable facts from the source (format, file, header fields).
    history : list of dict
        Processing steps, each ``{"step", "args", "gpr3d", "time"}``.
    """

    data: np.ndarray
    dt_s: float
    t0_s: float = 0.0
    timestamps_s: np.ndarray | None = None
    positions_xyz: np.ndarray | None = None
    orientations_quat_wxyz: np.ndarray | None = None
    offset_m: float = 0.0
    frequency_hz: float | None = None
    eps_r: float | None = None
    metadata: dict = field(default_factory=dict)
    history: list = field(default_factory=list)

    # ------------------------------------------------------------------ validation
    def __post_init__(self):
        data = np.asarray(self.data)
        if data.ndim == 1:
            data = data[None, :]
        if data.ndim != 2:
            raise InvalidDataError(f"data must be 2-D (n_traces, n_samples), got shape {data.shape}")
        if data.shape[0] < 1:
            raise InvalidDataError("survey has zero traces")
        if data.shape[1] < 2:
            raise InvalidDataError(f"traces need at least 2 samples, got {data.shape[1]}")
        if not np.issubdtype(data.dtype, np.number) or np.iscomplexobj(data):
            raise InvalidDataError(f"data must be real numbers, got dtype {data.dtype}")
        data = np.ascontiguousarray(data, dtype=np.float32)
        rows = max(1, (1 << 22) // data.shape[1])  # blocks of ~4 M samples: no file-sized mask for a large record
        bad = sum(int(np.count_nonzero(~np.isfinite(data[i : i + rows]))) for i in range(0, data.shape[0], rows))
        if bad:
            raise InvalidDataError(f"data holds {bad} NaN/inf samples")
        self.data = data
        self.dt_s = _optional_float("dt_s", self.dt_s, positive=True)
        if self.dt_s < 1e-15:
            raise InvalidDataError(f"dt_s = {self.dt_s:g} s is implausible for GPR (no radar or FDTD model samples "
                                   "faster than 1e-15 s)")
        if self.dt_s > 1e-3:
            raise InvalidDataError(
                f"dt_s = {self.dt_s} s is implausible for GPR (give the sample interval in seconds, e.g. 1e-10)"
            )
        self.t0_s = _optional_float("t0_s", self.t0_s)
        self.offset_m = _optional_float("offset_m", self.offset_m, minimum=0.0)
        self.frequency_hz = _optional_float("frequency_hz", self.frequency_hz, positive=True)
        self.eps_r = _optional_float("eps_r", self.eps_r, minimum=1.0)
        n = data.shape[0]
        shapes = {"timestamps_s": (n,), "positions_xyz": (n, 3), "orientations_quat_wxyz": (n, 4)}
        for name in _PER_TRACE:
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.array(value, dtype=np.float64)
            if arr.shape != shapes[name]:
                raise InvalidDataError(f"{name} must have shape {shapes[name]}, got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise InvalidDataError(f"{name} holds NaN/inf values")
            if name == "orientations_quat_wxyz":
                try:
                    arr = normalize_quat(arr)
                except ValueError as exc:
                    raise InvalidDataError(f"{name}: {exc}") from None
            setattr(self, name, arr)
        if not isinstance(self.metadata, dict):
            raise InvalidDataError("metadata must be a dict")
        self.history = list(self.history)

    # ------------------------------------------------------------------ shape and axes
    @property
    def n_traces(self) -> int:
        return self.data.shape[0]

    @property
    def n_samples(self) -> int:
        return self.data.shape[1]

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape

    def __len__(self) -> int:
        return self.n_traces

    @property
    def times_s(self) -> np.ndarray:
        """Time of each sample from the first recorded sample (s), ``(n_samples,)``."""
        return np.arange(self.n_samples) * self.dt_s

    @property
    def twt_s(self) -> np.ndarray:
        """Two-way time below the surface, ``times_s - t0_s`` (s)."""
        return self.times_s - self.t0_s

    @property
    def time_window_s(self) -> float:
        """Recorded time range (s): ``n_samples * dt_s``."""
        return self.n_samples * self.dt_s

    def depths_m(self, eps_r: float | None = None) -> np.ndarray:
        """Depth of each sample (m) for a constant ``eps_r`` (default: the survey's hint).

        Samples before time zero get negative depths (mirrored), so the axis stays monotonic.
        """
        eps = self.eps_r if eps_r is None else eps_r
        if eps is None:
            raise InvalidDataError("no eps_r given and the survey has no eps_r hint")
        twt = self.twt_s
        return np.sign(twt) * twt_to_depth(np.abs(twt), eps, self.offset_m)

    @property
    def headings_rad(self) -> np.ndarray | None:
        """Antenna heading per trace (rad from world x, about z), from the orientations."""
        if self.orientations_quat_wxyz is None:
            return None
        return yaw_from_quat(self.orientations_quat_wxyz)

    @property
    def distances_m(self) -> np.ndarray | None:
        """Cumulative path length along the antenna positions (m), or None."""
        if self.positions_xyz is None:
            return None
        steps = np.linalg.norm(np.diff(self.positions_xyz, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    # ------------------------------------------------------------------ copies and slices
    def copy(self) -> "Survey":
        """A deep copy."""
        return _copy.deepcopy(self)

    def replace(self, **changes) -> "Survey":
        """A new Survey with some fields changed (validated again)."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        unknown = set(changes) - set(values)
        if unknown:
            raise InvalidDataError(f"unknown Survey field(s): {sorted(unknown)}")
        values.update(changes)
        values["metadata"] = _copy.deepcopy(values["metadata"])
        values["history"] = _copy.deepcopy(values["history"])
        return Survey(**values)

    def with_headings(self, headings_rad) -> "Survey":
        """A new Survey whose orientations are yaw rotations by ``headings_rad`` (per trace or one)."""
        h = np.broadcast_to(np.asarray(headings_rad, dtype=float), (self.n_traces,))
        return self.replace(orientations_quat_wxyz=quat_from_yaw(h))

    def __getitem__(self, index) -> "Survey":
        """Select traces: a slice, an integer, an integer array or a boolean mask -> Survey."""
        if isinstance(index, tuple):
            raise InvalidDataError("Survey indexing selects traces only: use survey[i:j]")
        if isinstance(index, (int, np.integer)):
            i = int(index)
            if not -self.n_traces <= i < self.n_traces:
                raise IndexError(f"trace {i} out of range for {self.n_traces} traces")
            index = slice(i % self.n_traces, i % self.n_traces + 1)
        sel = np.arange(self.n_traces)[index]
        if sel.size == 0:
            raise InvalidDataError("selection holds zero traces")
        changes: dict[str, Any] = {"data": self.data[sel]}
        for name in _PER_TRACE:
            value = getattr(self, name)
            changes[name] = None if value is None else value[sel]
        out = self.replace(**changes)
        if not (isinstance(index, slice) and index == slice(None)):
            src = self.metadata.get("trace_index_source")
            base = np.arange(self.n_traces) if src is None else np.asarray(src)
            out.metadata["trace_index_source"] = base[sel].tolist()
        return out

    def equals(self, other: "Survey") -> bool:
        """Exact equality of every field (arrays bit-for-bit, metadata and history)."""
        if not isinstance(other, Survey):
            return False
        for f in fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if a is None or b is None or a.shape != b.shape or a.dtype != b.dtype:
                    return False
                if not np.array_equal(a, b):
                    return False
            elif a != b:
                return False
        return True

    def __repr__(self) -> str:
        fmt = self.metadata.get("format", "?")
        parts = [
            f"{self.n_traces} traces x {self.n_samples} samples",
            f"dt={self.dt_s * 1e9:.4g} ns",
            f"window={self.time_window_s * 1e9:.4g} ns",
        ]
        if self.frequency_hz:
            parts.append(f"f={self.frequency_hz / 1e6:.4g} MHz")
        if self.eps_r:
            parts.append(f"eps_r={self.eps_r:.3g}")
        if self.positions_xyz is not None:
            parts.append("poses" if self.orientations_quat_wxyz is not None else "positions")
        if self.history:
            parts.append(f"{len(self.history)} steps")
        return f"Survey({fmt}: " + ", ".join(parts) + ")"

    # ------------------------------------------------------------------ processing
    def _derive(self, step: str, args: dict, **changes) -> "Survey":
        """A new Survey with ``changes`` applied and ``step`` appended to the history."""
        from gpr3d import __version__

        out = self.replace(**changes)
        out.history.append(
            {
                "step": step,
                "args": _jsonable(args),
                "gpr3d": __version__,
                "time": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            }
        )
        return out

    def apply(self, step: str, **kwargs) -> "Survey":
        """Run a named processing step (see :data:`gpr3d.processing.steps.STEPS`), through the ``"step"`` plug-in."""
        return _plugin("step")(self, step, **kwargs)

    def time_zero(self, **kwargs) -> "Survey":
        """Estimate time zero and (by default) cut the samples before it; see :func:`gpr3d.processing.timezero.estimate_time_zero`."""
        return self.apply("time_zero", **kwargs)

    def dewow(self, **kwargs) -> "Survey":
        """Remove the low-frequency 'wow' with a running mean; see :func:`gpr3d.processing.dewow`."""
        return self.apply("dewow", **kwargs)

    def remove_dc(self, **kwargs) -> "Survey":
        """Subtract each trace's mean; see :func:`gpr3d.processing.background.remove_dc`."""
        return self.apply("remove_dc", **kwargs)

    def remove_background(self, **kwargs) -> "Survey":
        """Subtract the mean or median trace; see :func:`gpr3d.processing.background.remove_background`."""
        return self.apply("remove_background", **kwargs)

    def gain_tpow(self, **kwargs) -> "Survey":
        """Multiply by a power of two-way time; see :func:`gpr3d.processing.gain.gain_tpow`."""
        return self.apply("gain_tpow", **kwargs)

    def gain_sec(self, **kwargs) -> "Survey":
        """Spreading and exponential compensation; see :func:`gpr3d.processing.gain.gain_sec`."""
        return self.apply("gain_sec", **kwargs)

    def gain_agc(self, **kwargs) -> "Survey":
        """Automatic gain control; see :func:`gpr3d.processing.gain.gain_agc`."""
        return self.apply("gain_agc", **kwargs)

    def bandpass(self, **kwargs) -> "Survey":
        """Zero-phase Butterworth band-pass; see :func:`gpr3d.processing.filters.bandpass`."""
        return self.apply("bandpass", **kwargs)

    def envelope(self, **kwargs) -> "Survey":
        """Instantaneous amplitude (Hilbert envelope); see :func:`gpr3d.processing.envelope`."""
        return self.apply("envelope", **kwargs)

    def resample_spacing(self, **kwargs) -> "Survey":
        """Traces at a constant spacing along the path; see :func:`gpr3d.processing.resample.resample_traces`."""
        return self.apply("resample_spacing", **kwargs)

    # ------------------------------------------------------------------ files
    def save(self, path) -> None:
        """Write the survey losslessly to gpr3d's HDF5 schema (atomically), through the ``"save"`` plug-in."""
        _plugin("save")(self, path)

    @classmethod
    def load(cls, path) -> "Survey":
        """Read a survey written by :meth:`save`, through the ``"load"`` plug-in."""
        return _plugin("load")(path)
