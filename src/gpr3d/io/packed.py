"""Reader of packed labelled datasets (schema ``gpr3d.packed_dataset`` v1).

The writer and COCO export live with the simulator (:mod:`gpr3d.simulation.packed`);
the reader lives here so that detection and inversion can read datasets without
depending on simulation. ``ds[i]`` gives ``(Survey, labels dict)``; the scene is
kept as the stored JSON object (``ds.scene_dict(i)``).
"""

from __future__ import annotations

import json

import h5py
import numpy as np

from gpr3d.core.errors import FormatError
from gpr3d.io._common import check_file, check_hdf5_survives, hdf5_errors

__all__ = ["PackedDataset", "SCHEMA", "labelled_records"]

SCHEMA = "gpr3d.packed_dataset"


class PackedDataset:
    """Read a packed dataset: ``len(ds)``, ``ds[i] -> (Survey, labels dict)``."""

    def __init__(self, path):
        self.path = check_file(path)
        check_hdf5_survives(self.path)
        with hdf5_errors(self.path), h5py.File(self.path, "r") as f:
            if f.attrs.get("schema") != SCHEMA:
                raise FormatError(self.path, "not a gpr3d packed dataset")
            self.scale = f["scale"][()]
            self.dt_s = f["dt_s"][()]
            self.index = f["index"][()]
            self.manifest = json.loads(f.attrs["manifest_json"])
            self.config = json.loads(f.attrs["config_json"])
            self.regenerate = f.attrs.get("regenerate", "")
            self.shape = f["data"].shape
            # records of different lengths are zero-padded; n_traces keeps each length
            self.n_traces = f["n_traces"][()] if "n_traces" in f else np.full(len(self.index), self.shape[1])

    def __len__(self) -> int:
        return len(self.index)

    def labels(self, i: int) -> dict:
        with h5py.File(self.path, "r") as f:
            return json.loads(f["labels_json"][i])

    def scene_dict(self, i: int) -> dict:
        """The scene of sample ``i`` as stored (JSON object)."""
        with h5py.File(self.path, "r") as f:
            return json.loads(f["scene_json"][i])

    def array(self, i: int) -> np.ndarray:
        """B-scan ``i`` as float32 in its original amplitude units, ``(n_traces, n_samples)``."""
        with h5py.File(self.path, "r") as f:
            return f["data"][i, : int(self.n_traces[i])].astype(np.float32) * self.scale[i]

    def __getitem__(self, i: int):
        from gpr3d.core.survey import Survey

        if not -len(self) <= i < len(self):
            raise IndexError(i)
        i = i % len(self)
        scene = self.scene_dict(i)
        data = self.array(i)
        x = scene["x_start_m"] + scene["trace_step_m"] * np.arange(data.shape[0])
        pos = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
        ant = scene["antenna"]
        s = Survey(data=data, dt_s=float(self.dt_s[i]), positions_xyz=pos, offset_m=ant["offset_m"],
                   frequency_hz=ant["frequency_hz"], eps_r=scene["medium"]["eps_r"],
                   metadata={"format": "packed", "path": str(self.path), "index": int(self.index[i]),
                             "scene": scene})
        return s, self.labels(i)


def labelled_records(source, *, n: int | None = None, last: bool = False):
    """``(Survey, labels dict)`` of every record of a packed file or a ``gpr3d simulate`` folder.

    ``n`` limits the count (the first ``n``, or the last ``n`` with ``last``). A folder's
    samples are read in index order from ``samples/NNNNNN/{bscan.h5,labels.json}``.
    """
    from pathlib import Path

    src = Path(source)
    if src.is_dir():
        from gpr3d.io.registry import read

        folders = sorted(p for p in (src / "samples").glob("[0-9]" * 6) if p.is_dir()) \
            if (src / "samples").is_dir() else []
        if not folders:
            raise FormatError(src, "no samples/NNNNNN folders: not a gpr3d simulate dataset")
        folders = folders if n is None else (folders[-n:] if last else folders[:n])
        for d in folders:
            lab = d / "labels.json"
            if not lab.exists():
                raise FormatError(d, "sample folder has no labels.json")
            yield read(d / "bscan.h5"), json.loads(lab.read_text())
        return
    ds = PackedDataset(src)
    idx = range(len(ds))
    if n is not None:
        idx = idx[-n:] if last else idx[:n]
    for i in idx:
        yield ds[i]
