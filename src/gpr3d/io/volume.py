"""Migrated volumes on disk: the ``gpr3d.volume`` HDF5 schema (read and written) and VTK image data for ParaView.

``volume.h5``: attributes ``schema = "gpr3d.volume"``, ``schema_version = 1``, ``gpr3d_version``, ``grid_json``
(:meth:`~gpr3d.core.grid.Grid3D.to_dict` as JSON), ``axes``, and any others the writer passes (``eps_r``, ``source``); one float32
dataset of the grid's shape ``(nx, ny, nd)`` per volume (``image``, ``envelope``, ``noise_map``, ``fold``), x, y,
then depth positive down, in metres.

``volume.vti``: the same volumes as VTK point data, z up (depth runs downwards from the top of the block).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gpr3d import __version__
from gpr3d.core.atomic import atomic_path
from gpr3d.core.errors import FormatError
from gpr3d.core.grid import Grid3D
from gpr3d.io._common import check_file, check_hdf5_survives, hdf5_errors

__all__ = ["SCHEMA", "SCHEMA_VERSION", "Volume", "read_volume", "write_volume", "write_vti"]

SCHEMA = "gpr3d.volume"
SCHEMA_VERSION = 1
AXES = "x, y, depth (positive down), metres"


def _store(f, name: str, a, dtype=np.float32, *, compress: bool = True) -> None:
    """One dataset of an output file: ``a`` as ``dtype``, gzip level 4 with the shuffle filter (every array gpr3d
    writes here), or contiguous and uncompressed (``compress=False``: a reconstruction's volumes, whose float32
    noise gzip shrinks by a sixth in five times the time of writing them plain)."""
    if compress:
        f.create_dataset(name, data=np.asarray(a, dtype), compression="gzip", compression_opts=4, shuffle=True)
    else:
        f.create_dataset(name, data=np.asarray(a, dtype))


def _h5_output(path):
    """The atomic temporary beside ``path`` that an HDF5 output is written into."""
    return atomic_path(path, suffix=".h5.part")


@dataclass
class Volume:
    """A ``volume.h5`` read back: its grid, its volumes by name and its other attributes."""

    grid: Grid3D
    arrays: dict = field(default_factory=dict)
    attrs: dict = field(default_factory=dict)


def write_volume(path, grid: Grid3D, arrays: dict, **attrs) -> Path:
    """Write ``arrays`` (name -> ``grid.shape`` array; None values are left out) and ``attrs`` to ``path``
    (atomically; float32, uncompressed: gzip shrank them by a sixth in five times the time)."""
    import h5py

    for name, a in arrays.items():
        if a is not None and np.shape(a) != grid.shape:
            raise ValueError(f"volume {name!r} is {np.shape(a)}, the grid is {grid.shape}")
    path = Path(path)
    with _h5_output(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"schema": SCHEMA, "schema_version": SCHEMA_VERSION, "gpr3d_version": __version__,
                            "grid_json": json.dumps(grid.to_dict()), "axes": AXES,
                            **{k: v for k, v in attrs.items() if v is not None}})
            for name, a in arrays.items():
                if a is not None:
                    _store(f, name, a, compress=False)
    return path


def read_volume(path, names=None) -> Volume:
    """Read a ``volume.h5`` (all its volumes, or those in ``names``); a file that is not one, or is damaged, gives
    one :class:`~gpr3d.core.errors.FormatError` naming the problem."""
    import h5py

    from gpr3d.core.errors import InvalidDataError

    path = check_file(path)
    check_hdf5_survives(path)
    with hdf5_errors(path), h5py.File(path, "r") as f:
        schema = f.attrs.get("schema")
        schema = schema.decode() if isinstance(schema, bytes) else schema
        if schema != SCHEMA:
            raise FormatError(path, f"not a gpr3d volume (schema attribute {schema!r}, expected {SCHEMA!r})")
        version = int(f.attrs.get("schema_version", -1))
        if version > SCHEMA_VERSION:
            raise FormatError(path, f"gpr3d.volume schema version {version} is newer than this gpr3d reads "
                                    f"({SCHEMA_VERSION}): upgrade gpr3d")
        try:
            grid = Grid3D.from_dict(json.loads(f.attrs["grid_json"]))
        except (json.JSONDecodeError, InvalidDataError) as exc:
            raise FormatError(path, f"its grid_json attribute is not a grid ({str(exc)[:120]})") from None
        wanted = list(f.keys()) if names is None else list(names)
        arrays = {}
        for name in wanted:
            if name not in f:
                raise FormatError(path, f"holds no volume {name!r} (it has {', '.join(sorted(f.keys())) or 'none'})")
            if f[name].shape != grid.shape:
                raise FormatError(path, f"volume {name!r} is {f[name].shape}, its grid is {grid.shape}")
            a = f[name][()].astype(np.float32)
            if not np.all(np.isfinite(a)):
                raise FormatError(path, f"volume {name!r} holds NaN or infinite values")
            arrays[name] = a
        attrs = {k: (v.decode() if isinstance(v, bytes) else v.item() if hasattr(v, "item") else v)
                 for k, v in f.attrs.items() if k != "grid_json"}
    return Volume(grid=grid, arrays=arrays, attrs=attrs)


def write_vti(path, grid: Grid3D, arrays: dict) -> Path:
    """Write ``arrays`` (name -> ``grid.shape``; None left out) as VTK image data (``.vti``, ParaView): z up, so
    depth runs downwards from the top of the block.

    The XML image-data layout of VTK's file formats, its arrays float32 little-endian in one raw appended block,
    each behind its byte count (UInt64), x fastest. Written here rather than by pyevtk, which packs every value
    through a Python argument list (0.2 s per 4 M voxels, against a few milliseconds for the bytes themselves)."""
    named = {str(k): np.asarray(a) for k, a in arrays.items() if a is not None}
    for k, a in named.items():
        if a.shape != grid.shape:
            raise ValueError(f"volume {k!r} has shape {a.shape}, the grid {grid.shape}")
    z_bottom = -(grid.d0 + (grid.nd - 1) * grid.dd)
    extent = f"0 {grid.nx - 1} 0 {grid.ny - 1} 0 {grid.nd - 1}"
    nbytes = 4 * int(np.prod(grid.shape))
    entries = "".join(f'<DataArray Name="{k}" NumberOfComponents="1" type="Float32" format="appended" '
                      f'offset="{i * (8 + nbytes)}"/>\n' for i, k in enumerate(named))
    scalars = f' Scalars="{next(iter(named))}"' if named else ""
    head = ('<?xml version="1.0"?>\n'
            '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n'
            f'<ImageData WholeExtent="{extent}" Origin="{grid.x0!r} {grid.y0!r} {z_bottom!r}" '
            f'Spacing="{grid.dx!r} {grid.dy!r} {grid.dd!r}">\n<Piece Extent="{extent}">\n'
            f"<PointData{scalars}>\n{entries}</PointData>\n</Piece>\n</ImageData>\n"
            '<AppendedData encoding="raw">\n_')
    path = Path(path)
    with atomic_path(path, suffix=".part.vti") as tmp:
        with open(tmp, "wb") as f:
            f.write(head.encode("ascii"))
            for a in named.values():
                f.write(np.uint64(nbytes).astype("<u8").tobytes())
                # x fastest, then y, then z up: the depth axis reversed, the axes' order turned round
                np.ascontiguousarray(a[:, :, ::-1].transpose(2, 1, 0), dtype="<f4").tofile(f)
            f.write(b"\n</AppendedData>\n</VTKFile>\n")
    return path


def write_cscan(path, cs) -> Path:
    """Write a :class:`~gpr3d.processing.cscan.CScan` to HDF5 (atomically): ``values`` (slices, x, y) and the
    georeference as attributes (``x0``, ``y0``: centre of cell [0, 0], ``cell_m``, site frame), ``t_start_s``,
    ``window_s`` and, with an eps_r, ``depth_m``."""
    import h5py

    path = Path(path)
    with _h5_output(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"schema": "gpr3d.cscan", "schema_version": 1, "gpr3d_version": __version__,
                            "x0": cs.x0, "y0": cs.y0, "cell_m": cs.cell_m, "window_s": cs.window_s,
                            "axes": "slice, x (east), y (north); cell centres x0 + i * cell_m",
                            **({"eps_r": cs.eps_r} if cs.eps_r is not None else {})})
            _store(f, "values", cs.values)
            _store(f, "t_start_s", cs.t_start_s, np.float64)
            if cs.depth_m is not None:
                _store(f, "depth_m", cs.depth_m, np.float64)
    return path


def read_cscan(path):
    """Read what :func:`write_cscan` wrote, as a :class:`~gpr3d.processing.cscan.CScan`."""
    import h5py

    from gpr3d.core.grid import CScan

    p = check_file(path)
    try:
        with h5py.File(p, "r") as f:
            if f.attrs.get("schema") != "gpr3d.cscan":
                raise FormatError(p, "is not a gpr3d C-scan file")
            a = dict(f.attrs)
            return CScan(f["values"][()], float(a["x0"]), float(a["y0"]), float(a["cell_m"]), f["t_start_s"][()],
                         float(a["window_s"]), f["depth_m"][()] if "depth_m" in f else None,
                         float(a["eps_r"]) if "eps_r" in a else None)
    except (OSError, KeyError) as exc:
        raise FormatError(p, f"unreadable C-scan ({exc})") from None


def write_profile(path, prof) -> Path:
    """Write a migrated profile (:class:`~gpr3d.migration.profile.ProfileImage`: ``image (along, depth)``,
    ``along_m``, ``depth_m``, ``method``, ``eps_r``) to HDF5, atomically."""
    import h5py

    path = Path(path)
    with _h5_output(path) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"schema": "gpr3d.profile", "schema_version": 1, "gpr3d_version": __version__,
                            "method": prof.method, "eps_r": prof.eps_r, "axes": "along (m), depth (m, down)"})
            _store(f, "image", prof.image)
            _store(f, "along_m", prof.along_m, np.float64)
            _store(f, "depth_m", prof.depth_m, np.float64)
    return path
