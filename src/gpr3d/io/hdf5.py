"""gpr3d's own HDF5 file: lossless, versioned storage of one or more :class:`~gpr3d.core.survey.Survey`.

Schema ``gpr3d.survey`` version 1::

    /                     attrs: schema="gpr3d.survey", schema_version=1, gpr3d_version
    /surveys/<i>/data     (n_traces, n_samples) float32, gzip + shuffle
    /surveys/<i>/timestamps_s, positions_xyz, orientations_quat_wxyz   (float64, when present)
    /surveys/<i>          attrs: dt_s, t0_s, offset_m, frequency_hz?, eps_r?,
                          metadata_json, history_json

Writes are atomic (a temporary file replaced in one step).
"""

from __future__ import annotations

import json

import h5py

from gpr3d.core.atomic import atomic_path
from gpr3d.core.errors import FormatError
from gpr3d.core.survey import Survey
from gpr3d.io._common import check_file, check_hdf5_survives, hdf5_errors, header_count

__all__ = ["SCHEMA", "SCHEMA_VERSION", "write_survey", "write_surveys", "read_surveys", "read_survey", "is_gpr3d_h5"]

SCHEMA = "gpr3d.survey"
SCHEMA_VERSION = 1
_ARRAYS = ("timestamps_s", "positions_xyz", "orientations_quat_wxyz")
_SCALARS = ("dt_s", "t0_s", "offset_m", "frequency_hz", "eps_r")


def _schema(f):
    """The file's schema attribute as a string, or what it holds instead (an array, a number, None) as itself."""
    v = f.attrs.get("schema")
    if isinstance(v, bytes):
        v = v.decode("latin-1")
    return v if isinstance(v, str) or v is None else repr(v)


def is_gpr3d_h5(path) -> bool:
    try:
        with open(path, "rb") as fh:
            if fh.read(8) != b"\x89HDF\r\n\x1a\n":
                return False
        with h5py.File(path, "r") as f:
            return _schema(f) == SCHEMA
    except Exception:  # noqa: BLE001 - detection never raises
        return False


def write_surveys(surveys, path) -> None:
    """Write a list of surveys (e.g. the channels of one recording) to ``path`` atomically."""
    from gpr3d import __version__

    surveys = list(surveys)
    if not surveys:
        raise ValueError("nothing to write: empty list of surveys")
    with atomic_path(path, suffix=".h5.part") as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["schema"] = SCHEMA
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["gpr3d_version"] = __version__
            root = f.create_group("surveys")
            for i, s in enumerate(surveys):
                g = root.create_group(str(i))
                g.create_dataset("data", data=s.data, compression="gzip", compression_opts=4, shuffle=True)
                for name in _ARRAYS:
                    value = getattr(s, name)
                    if value is not None:
                        g.create_dataset(name, data=value)
                for name in _SCALARS:
                    value = getattr(s, name)
                    if value is not None:
                        g.attrs[name] = float(value)
                g.attrs["metadata_json"] = json.dumps(s.metadata, allow_nan=True)
                g.attrs["history_json"] = json.dumps(s.history, allow_nan=True)


def write_survey(survey: Survey, path) -> None:
    """Write one survey to ``path`` atomically."""
    write_surveys([survey], path)


def read_surveys(path) -> list[Survey]:
    """Read every survey in a gpr3d HDF5 file."""
    p = check_file(path)
    check_hdf5_survives(p)
    with hdf5_errors(p):
        return _read_surveys(p)


def _read_surveys(p) -> list[Survey]:
    with h5py.File(p, "r") as f:
        if _schema(f) != SCHEMA:
            raise FormatError(p, f"not a gpr3d survey file (schema attribute {_schema(f)!r})")
        version = header_count(p, "schema_version", f.attrs.get("schema_version", -1), lo=-1, hi=10**6)
        if version > SCHEMA_VERSION:
            raise FormatError(p, f"written with schema version {version}; this gpr3d reads up to {SCHEMA_VERSION}: upgrade gpr3d")
        if "surveys" not in f or not len(f["surveys"]):
            raise FormatError(p, "holds no surveys")
        out = []
        size = p.stat().st_size
        for key in sorted(f["surveys"], key=int):
            g = f["surveys"][key]
            _check_declared(p, key, g, size)
            try:
                kwargs = {"data": g["data"][()]}
                for name in _ARRAYS:
                    kwargs[name] = g[name][()] if name in g else None
                for name in _SCALARS:
                    kwargs[name] = float(g.attrs[name]) if name in g.attrs else None
                kwargs["t0_s"] = kwargs["t0_s"] or 0.0
                kwargs["offset_m"] = kwargs["offset_m"] or 0.0
                kwargs["metadata"] = json.loads(g.attrs["metadata_json"])
                kwargs["history"] = json.loads(g.attrs["history_json"])
            except (KeyError, ValueError, OSError) as exc:
                raise FormatError(p, f"survey {key} is incomplete or corrupt: {exc}") from None
            json_names = {dict: "an object", list: "a list", str: "a string", int: "a number", float: "a number",
                          bool: "true/false", type(None): "null"}
            for name, want in (("metadata", dict), ("history", list)):
                if not isinstance(kwargs[name], want):
                    raise FormatError(p, f"survey {key}: its {name}_json holds {json_names[type(kwargs[name])]}, "
                                         f"not {json_names[want]}")
            try:
                out.append(Survey(**kwargs))
            except ValueError as exc:
                raise FormatError(p, f"survey {key}: {exc}") from None
        return out


#: a data set may declare this much more than the file's size (compression) before its claim is refused
_MAX_DECLARED_RATIO = 64
_MAX_UNCHECKED_BYTES = 256 << 20


def _check_declared(p, key, g, file_bytes: int) -> None:
    """What survey ``key`` declares, checked before anything is allocated: a 2-D numeric data set of no more bytes
    than the file can hold (compressed), and its sample interval."""
    if "data" not in g or not isinstance(g["data"], h5py.Dataset):
        raise FormatError(p, f"survey {key} has no data set 'data'")
    ds = g["data"]
    if ds.ndim != 2 or ds.dtype.kind not in "iuf":
        raise FormatError(p, f"survey {key}: data is a {ds.ndim}-D {ds.dtype} data set, not a 2-D array of numbers")
    declared = int(ds.size) * ds.dtype.itemsize
    if declared > _MAX_UNCHECKED_BYTES and declared > _MAX_DECLARED_RATIO * file_bytes:
        raise FormatError(p, f"survey {key} declares a {'x'.join(map(str, ds.shape))} data set "
                             f"({declared / 2**30:.3g} GiB) in a {file_bytes:,}-byte file: truncated or corrupt")
    if "dt_s" not in g.attrs:
        raise FormatError(p, f"survey {key} has no dt_s attribute (the sample interval, in seconds)")


def read_survey(path, channel: int = 0) -> Survey:
    """Read one survey from a gpr3d HDF5 file."""
    surveys = read_surveys(path)
    if not 0 <= channel < len(surveys):
        raise FormatError(path, f"has {len(surveys)} survey(s); channel {channel} does not exist")
    return surveys[channel]
