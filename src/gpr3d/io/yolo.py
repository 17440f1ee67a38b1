"""YOLO-format labelled B-scans: a folder of ``images/`` and ``labels/``, or a ``data.yaml``.

Each picture becomes a training or evaluation record ``(Survey, labels dict)`` as
:func:`gpr3d.io.userlabels.read_user_labels` makes them: one trace per pixel column,
one sample per row, ``s_per_px`` seconds apart (the time axis must be given: a
picture carries none), and labels in the record's traces and seconds.

A label file holds one box a line, ``class cx cy w h`` normalised to 0..1 by the
picture's width and height (YOLO's convention); a line of a polygon (``class x1 y1
x2 y2 ...``, YOLO's segmentation format) counts as the box around it. A picture
without a label file is a picture with no targets. The label file of
``.../images/NAME.png`` is ``.../labels/NAME.txt``.

Class names come from ``names`` (a list in class order), else from the
``data.yaml``'s ``names``; each is mapped onto a gpr3d target kind by ``kinds``
(``{"pipe": "pvc_pipe"}`` or ``"pipe=pvc_pipe,steel=rebar"``), else by
:data:`~gpr3d.io.userlabels.KIND_ALIASES` (P-GPR's ``steel`` is ``rebar``); a name
that is no kind becomes ``"target"``. Boxes are taken as tight around the hyperbola
(its apex a tenth of the way down the box, ``docs/labels.md``).

>>> recs = read_yolo("pgpr_1600MHz/val", names=["steel", "pipe"], kinds="pipe=pvc_pipe",
...                  pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9)      # doctest: +SKIP
"""

from __future__ import annotations

import math
from fnmatch import fnmatch
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.io.coco import CATEGORIES, PixelMap
from gpr3d.io.userlabels import IMAGE_SUFFIXES, _kind, _labels, _picture_survey, check_frequency, parse_pixel_map

__all__ = ["read_yolo", "parse_kinds", "yolo_images", "is_yolo"]

SPLITS = ("train", "val", "test")


def parse_kinds(spec) -> dict:
    """``{"class name": "kind"}`` from ``"pipe=pvc_pipe,steel=rebar"`` or a dict; every kind checked."""
    if spec is None:
        return {}
    if isinstance(spec, str):
        out = {}
        for part in filter(None, (p.strip() for p in spec.split(","))):
            name, sep, kind = part.partition("=")
            if not sep or not name.strip() or not kind.strip():
                raise InvalidDataError(f"kinds {spec!r}: expected name=kind pairs, got {part!r}")
            out[name.strip()] = kind.strip()
        spec = out
    if not isinstance(spec, dict):
        raise InvalidDataError(f"kinds must be name=kind pairs or an object, got {type(spec).__name__}")
    for name, kind in spec.items():
        if kind not in CATEGORIES:
            raise InvalidDataError(f"kinds: {name}={kind}: {kind!r} is not a target kind ({', '.join(CATEGORIES)})")
    return {str(k).strip().lower(): v for k, v in spec.items()}


def _yaml(path: Path) -> dict:
    import yaml

    try:
        doc = yaml.safe_load(path.read_text())
    except (UnicodeDecodeError, yaml.YAMLError) as exc:
        raise FormatError(path, f"not valid YAML ({str(exc).splitlines()[0][:100]})") from None
    if not isinstance(doc, dict):
        raise FormatError(path, "not a YOLO data file (expected a mapping with train/val and names)")
    return doc


def _names_of(doc: dict, path: Path) -> list[str] | None:
    names = doc.get("names")
    if names is None:
        return None
    if isinstance(names, dict):
        try:
            idx = sorted(int(k) for k in names)
        except (TypeError, ValueError):
            raise FormatError(path, f"names: class ids must be integers, got {sorted(map(str, names))}") from None
        if idx != list(range(len(idx))):
            raise FormatError(path, f"names: class ids must run 0..{len(idx) - 1}, got {idx}")
        return [str(names[k] if k in names else names[str(k)]) for k in idx]
    if isinstance(names, list) and names:
        return [str(n) for n in names]
    raise FormatError(path, "names must be a list or an id: name mapping")


def _images_in(entry, root: Path, where: Path) -> list[Path]:
    """The pictures a data.yaml split names: folders, list files (.txt, one path a line) or pictures."""
    items = entry if isinstance(entry, list) else [entry]
    out: list[Path] = []
    for item in items:
        p = Path(str(item))
        p = p if p.is_absolute() else root / p
        if p.is_dir():
            out.extend(yolo_images(p))
        elif p.suffix.lower() == ".txt" and p.is_file():
            for line in p.read_text().splitlines():
                if line.strip():
                    q = Path(line.strip())
                    out.append(q if q.is_absolute() else p.parent / q)
        elif p.suffix.lower() in IMAGE_SUFFIXES and p.is_file():
            out.append(p)
        else:
            raise FormatError(where, f"split entry {item!r}: no such folder, list file or picture ({p})")
    return out


def yolo_images(folder) -> list[Path]:
    """The pictures of a YOLO folder: ``folder/images/*`` when it exists, else ``folder/*``; sorted."""
    f = Path(folder)
    img = f / "images" if (f / "images").is_dir() else f
    return sorted(p for p in img.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def is_yolo(path) -> bool:
    """Whether ``path`` looks like a YOLO dataset (a data.yaml, or a folder with images/ and labels/)."""
    p = Path(path)
    if p.is_file():
        return p.suffix.lower() in (".yaml", ".yml")
    return (p / "images").is_dir() and (p / "labels").is_dir() or any(p.glob("data.y*ml"))


def _label_file(image: Path) -> Path:
    parts = list(image.parts)
    for i in range(len(parts) - 2, -1, -1):  # the last 'images' folder on the path becomes 'labels'
        if parts[i] == "images":
            parts[i] = "labels"
            return Path(*parts).with_suffix(".txt")
    return image.with_suffix(".txt")


def _read_boxes(lab: Path, width: int, height: int, n_names: int | None):
    """Pixel boxes ``[x0, y0, x1, y1]`` and class ids of one label file (empty if it is absent)."""
    if not lab.exists():
        return [], []
    boxes, ids = [], []
    try:
        text = lab.read_text()
    except UnicodeDecodeError:
        raise FormatError(lab, "not a text file of YOLO labels") from None
    for k, line in enumerate(text.splitlines(), 1):
        fields = line.split()
        if not fields:
            continue
        try:
            vals = [float(v) for v in fields]
        except ValueError:
            raise FormatError(lab, f"line {k}: {line.strip()[:60]!r} is not numbers (class cx cy w h)") from None
        if not all(math.isfinite(v) for v in vals):
            raise FormatError(lab, f"line {k}: holds NaN/inf")
        cls = vals[0]
        if cls != int(cls) or cls < 0 or (n_names is not None and cls >= n_names):
            known = f" (classes 0..{n_names - 1})" if n_names is not None else ""
            raise FormatError(lab, f"line {k}: class {fields[0]} is not a class id{known}")
        coords = vals[1:]
        if len(coords) == 4:
            cx, cy, w, h = coords
            x0, x1, y0, y1 = cx - w / 2, cx + w / 2, cy - h / 2, cy + h / 2
        elif len(coords) >= 6 and len(coords) % 2 == 0:  # a polygon: the box around it
            xs, ys = coords[0::2], coords[1::2]
            x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
        else:
            raise FormatError(lab, f"line {k}: {len(fields)} numbers; a box line is 'class cx cy w h'")
        if min(x0, y0) < -0.01 or max(x1, y1) > 1.01:
            raise FormatError(lab, f"line {k}: the box reaches outside 0..1 ({line.strip()[:60]}): "
                                   "YOLO boxes are normalised by the picture's size")
        if x1 <= x0 or y1 <= y0:
            raise FormatError(lab, f"line {k}: the box has no area")
        boxes.append([max(x0, 0.0) * width, max(y0, 0.0) * height, min(x1, 1.0) * width, min(y1, 1.0) * height])
        ids.append(int(cls))
    return boxes, ids


def read_yolo(path, *, split: str = "train", names=None, kinds=None, pixel_map=None,
              frequency_hz: float | None = None, pattern: str | None = None) -> list:
    """Labelled records ``[(Survey, labels dict), ...]`` of a YOLO dataset (see the module's text).

    Parameters
    ----------
    path : str or Path
        A ``data.yaml``, a folder holding one, or a folder with ``images/`` (and ``labels/``).
    split : {"train", "val", "test"}
        Which split of a ``data.yaml`` to read (a plain folder is read whole).
    names : list of str, optional
        Class names in id order (default: the ``data.yaml``'s; else the class ids as names).
    kinds : str or dict, optional
        Class name -> target kind (``"pipe=pvc_pipe"``), over :data:`~gpr3d.io.userlabels.KIND_ALIASES`.
    pixel_map : str or dict
        The pictures' time axis, ``s_per_px`` at least (:func:`~gpr3d.io.userlabels.parse_pixel_map`).
    frequency_hz : float, optional
        The radar's centre frequency (kept on the records; the detector's processing uses it).
    pattern : str, optional
        Only the pictures whose file name matches this glob (``"AIR_*"``: one radar's files of P-GPR).

    Returns
    -------
    list of (Survey, dict)
        One record per picture, labels with ``kind``, ``source_name``, ``box`` in traces and seconds.

    Raises
    ------
    FormatError
        A missing or malformed data file, label line or picture (the message names it).
    InvalidDataError
        A missing or wrong pixel map, split, class name or kind.
    """
    if split not in SPLITS:
        raise InvalidDataError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    if pixel_map is None:
        raise InvalidDataError(f"{path}: YOLO pictures carry no time axis; give a pixel map with s_per_px "
                               "(e.g. --pixel-map s_per_px=3.125e-11 for 8 ns over 256 rows)")
    pm = parse_pixel_map(pixel_map)
    check_frequency(frequency_hz)
    mapping = parse_kinds(kinds)
    p = Path(path)
    if not p.exists():
        raise FormatError(p, "no such file or folder")
    yaml_file = p if p.is_file() else next(iter(sorted(p.glob("data.y*ml"))), None)
    if yaml_file is not None:
        if yaml_file.suffix.lower() not in (".yaml", ".yml"):
            raise FormatError(yaml_file, "a YOLO dataset is a data.yaml or a folder with images/ and labels/")
        doc = _yaml(yaml_file)
        root = Path(str(doc.get("path") or "."))
        root = root if root.is_absolute() else yaml_file.parent / root
        if doc.get(split) is None:
            raise FormatError(yaml_file, f"names no {split!r} split (has {', '.join(s for s in SPLITS if doc.get(s))})")
        images = _images_in(doc[split], root, yaml_file)
        names = list(names) if names is not None else _names_of(doc, yaml_file)
    else:
        if not (p / "images").is_dir():
            raise FormatError(p, "not a YOLO dataset: no data.yaml and no images/ folder")
        images = yolo_images(p)
    if pattern is not None:
        images = [im for im in images if fnmatch(im.name, pattern)]
    if not images:
        raise FormatError(p, f"a YOLO dataset with no pictures ({split}" + (f", {pattern}" if pattern else "") + ")")
    n_names = len(names) if names is not None else None
    records = []
    for img in images:
        if not img.exists():
            raise FormatError(img, "named by the dataset, but no such picture")
        survey = _picture_survey(img, pm, frequency_hz)
        height, width = survey.n_samples, survey.n_traces
        boxes, ids = _read_boxes(_label_file(img), width, height, n_names)
        cls_names = [names[i] if names is not None else str(i) for i in ids]
        shown = [mapping.get(n.strip().lower()) or _kind(n) for n in cls_names]
        own = PixelMap(s_per_px=pm.s_per_px)  # trace = column, time = row * s_per_px
        # boxes in pixel corners: a column's centre is at +0.5
        px = [[b[0] - 0.5, b[1] - 0.5, b[2] - 0.5, b[3] - 0.5] for b in boxes]
        labels = _labels(survey, px, shown, own, img.name, tight=True)
        for lab, name in zip(labels["labels"], cls_names):
            lab["source_name"] = name
        labels["image"] = str(img)
        labels["image_size"] = [int(width), int(height)]
        records.append((survey, labels))
    return records


def records_summary(records) -> dict:
    """``{"records", "boxes", "by_kind": {kind: n}}`` of a list of labelled records."""
    kinds = [lab["kind"] for _, r in records for lab in r["labels"]]
    return {"records": len(records), "boxes": len(kinds),
            "by_kind": {str(k): int(n) for k, n in zip(*np.unique(kinds, return_counts=True))} if kinds else {}}
