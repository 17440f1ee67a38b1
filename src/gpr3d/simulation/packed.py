"""A compact, single-file form of a simulated dataset (for storing it in the repository).

``pack_dataset(DIR, FILE.h5)`` stores every sample's B-scan resampled in time to
``n_samples`` (default 512) as float16 scaled to +-1 (the scale kept per sample),
with its scene and labels as JSON, the manifest and the command that regenerates
it. :class:`PackedDataset` reads it back: ``ds[i]`` gives ``(Survey, labels)``;
:meth:`PackedDataset.export_coco` writes detector images and ``coco.json``.

Schema ``gpr3d.packed_dataset`` version 1::

    /data        (N, n_traces, n_samples) float16, gzip      B-scans / scale
    /n_traces    (N,) int64, only where records differ in length: record i is
                 data[i, :n_traces[i]] (the rest is zero padding)
    /scale       (N,) float32                                 per-sample max |amplitude|
    /dt_s        (N,) float64                                 resampled sample interval
    /index       (N,) int64                                   scene index (sample_scene(seed, index))
    /scene_json, /labels_json   (N,) UTF-8 strings
    attrs: schema, schema_version, gpr3d_version, manifest_json, config_json, regenerate
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from gpr3d import __version__
from gpr3d.core.atomic import atomic_path, atomic_write_text
from gpr3d.core.errors import GPR3DError
from gpr3d.io.packed import SCHEMA
from gpr3d.io.packed import PackedDataset as _PackedReader
from gpr3d.processing.image import resample_rows

__all__ = ["pack_dataset", "PackedDataset", "load_sample"]


def pack_dataset(folder, out, *, n_samples: int = 512, regenerate: str = "") -> dict:
    """Pack the samples of a ``gpr3d simulate`` folder into one compressed HDF5 file (atomically)."""
    import gpr3d

    folder = Path(folder)
    manifest_path = folder / "manifest.json"
    if not manifest_path.exists():
        raise GPR3DError(f"{folder}: no manifest.json (is this a gpr3d simulate folder?)")
    manifest = json.loads(manifest_path.read_text())
    config = json.loads((folder / "config.json").read_text()) if (folder / "config.json").exists() else {}
    entries = manifest["samples"]
    if not entries:
        raise GPR3DError(f"{folder}: the dataset holds no samples")
    arrays, scales, dts, idx, scenes, labels = [], [], [], [], [], []
    for e in entries:
        d = folder / "samples" / f"{e['index']:06d}"
        s = gpr3d.read(d / "bscan.h5")
        x = resample_rows(s.data, n_samples).astype(np.float64)
        scale = float(np.abs(x).max()) or 1.0
        arrays.append((x / scale).astype(np.float16))
        scales.append(scale)
        dts.append((s.n_samples - 1) * s.dt_s / (n_samples - 1))
        idx.append(e["index"])
        scenes.append((d / "scene.json").read_text())
        labels.append((d / "labels.json").read_text())
    n_traces = np.asarray([a.shape[0] for a in arrays], dtype=np.int64)
    ragged = bool(np.any(n_traces != n_traces[0]))
    if ragged:  # survey-scale records differ in length: pad with zeros, keep each length
        width = int(n_traces.max())
        arrays = [np.pad(a, ((0, width - a.shape[0]), (0, 0))) for a in arrays]
    str_t = h5py.string_dtype("utf-8")
    with atomic_path(out, suffix=".h5.part") as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"schema": SCHEMA, "schema_version": 1, "gpr3d_version": __version__,
                            "manifest_json": json.dumps(manifest), "config_json": json.dumps(config),
                            "regenerate": regenerate})
            f.create_dataset("data", data=np.stack(arrays), compression="gzip", compression_opts=6, shuffle=True,
                             chunks=(1,) + arrays[0].shape)
            f["scale"] = np.asarray(scales, dtype=np.float32)
            f["dt_s"] = np.asarray(dts)
            f["index"] = np.asarray(idx, dtype=np.int64)
            if ragged:
                f["n_traces"] = n_traces
            f.create_dataset("scene_json", data=np.asarray(scenes, dtype=object), dtype=str_t, compression="gzip")
            f.create_dataset("labels_json", data=np.asarray(labels, dtype=object), dtype=str_t, compression="gzip")
    return {"n": len(entries), "file": str(out), "bytes": Path(out).stat().st_size}


class PackedDataset(_PackedReader):
    """A packed dataset with its scenes as :class:`~gpr3d.simulation.scene.Scene` and COCO export."""

    def scene(self, i: int):
        from gpr3d.simulation.scene import Scene

        return Scene.from_dict(self.scene_dict(i))

    def export_coco(self, out_dir, *, image_height: int = 256) -> dict:
        """Write ``images/{index}.png`` and ``coco.json`` (labels in image pixels) into ``out_dir``."""
        from PIL import Image

        from gpr3d.io.coco import coco_dataset
        from gpr3d.processing.image import bscan_image

        out = Path(out_dir)
        (out / "images").mkdir(parents=True, exist_ok=True)
        items = []
        for i in range(len(self)):
            s, lab = self[i]
            name = f"images/{int(self.index[i]):06d}.png"
            with atomic_path(out / name, suffix=".png.part") as tmp:
                Image.fromarray(bscan_image(s, image_height)).save(tmp, format="png")
            items.append({"id": int(self.index[i]) + 1, "file_name": name, "n_traces": s.n_traces,
                          "n_samples": s.n_samples, "dt_s": s.dt_s, "eps_r": s.eps_r, "labels": lab["labels"]})
        coco = coco_dataset(items, image_height)
        atomic_write_text(out / "coco.json", json.dumps(coco, indent=1))
        return coco


def load_sample(source, index: int):
    """Sample ``index`` of a dataset folder or packed file: ``(Survey, labels dict)``."""
    import gpr3d

    source = Path(source)
    if source.is_dir():
        d = source / "samples" / f"{index:06d}"
        if not d.exists():
            raise GPR3DError(f"{source}: no sample {index}")
        return gpr3d.read(d / "bscan.h5"), json.loads((d / "labels.json").read_text())
    ds = PackedDataset(source)
    hits = np.nonzero(ds.index == index)[0]
    if not hits.size:
        raise GPR3DError(f"{source}: no sample {index}")
    return ds[int(hits[0])]
