"""Users' own labelled B-scans: COCO JSON or Pascal VOC XML, over radar files or plain images.

Each labelled image becomes a training record ``(Survey, labels dict)`` in the form
the simulator writes (boxes ``[trace_start, t_start_s, trace_end, t_end_s]`` in the
record's own traces and seconds from its first sample), so fine-tuning does not care
where the labels came from.

What an image's ``file_name`` (COCO) or ``<filename>``/``<path>`` (VOC) names, relative
to the label file's folder:

* **a radar file** (anything :func:`gpr3d.io.registry.read` reads): the record is the file. The
  image's pixels map onto it by, in this order: the image's ``gpr3d_pixel_map`` object
  (``{"trace0", "traces_per_px", "t0_s", "s_per_px"}``, see :class:`~gpr3d.io.coco.PixelMap`),
  the ``row_s`` field of gpr3d's own COCO export (one column per trace), or else the
  image spanning the whole record (``width`` x ``height`` pixels over all traces and samples).
* **a picture** (``.png``, ``.jpg``, ...; a screenshot of a B-scan): its grey levels
  become a record with one trace per column and one sample per row. Its time axis
  must be given: ``gpr3d_pixel_map`` in the image entry, or ``pixel_map`` for all
  pictures (``s_per_px`` at least). ``trace0``/``traces_per_px``/``t0_s`` of the map are
  kept in the record's metadata (to report in the original file's units).

Category names that are gpr3d target kinds (:data:`~gpr3d.io.coco.CATEGORIES`) are kept;
others become kind ``"target"``. The apex of an imported box is taken at its centre
trace and ``0.7`` periods below its top (the label rule) when the frequency is known,
else a tenth of the way down the box.
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.io._common import check_file
from gpr3d.io.coco import BOX_PAD_PERIODS, CATEGORIES, PixelMap

__all__ = ["read_user_labels", "read_picture", "parse_pixel_map", "check_frequency", "IMAGE_SUFFIXES",
           "KIND_ALIASES"]

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".gif"}
_MAP_KEYS = ("trace0", "traces_per_px", "t0_s", "s_per_px")


def parse_pixel_map(spec) -> PixelMap:
    """A :class:`~gpr3d.io.coco.PixelMap` from ``"s_per_px=1e-10,t0_s=0,traces_per_px=1,trace0=0"`` or a dict.

    ``s_per_px`` (seconds per pixel row) is required; the rest default to 0 / 1.
    """
    if isinstance(spec, PixelMap):
        return spec
    if isinstance(spec, str):
        items = {}
        for part in filter(None, (p.strip() for p in spec.split(","))):
            key, sep, val = part.partition("=")
            if not sep:
                raise InvalidDataError(f"pixel map {spec!r}: expected key=value pairs, got {part!r}")
            try:
                items[key.strip()] = float(val)
            except ValueError:
                raise InvalidDataError(f"pixel map {spec!r}: {key.strip()} = {val!r} is not a number") from None
        spec = items
    if not isinstance(spec, dict):
        raise InvalidDataError(f"pixel map must be key=value pairs or an object, got {type(spec).__name__}")
    unknown = set(spec) - set(_MAP_KEYS)
    if unknown:
        raise InvalidDataError(f"pixel map: unknown key(s) {sorted(unknown)} (use {', '.join(_MAP_KEYS)})")
    if "s_per_px" not in spec:
        raise InvalidDataError("pixel map needs s_per_px (seconds per pixel row)")
    vals = {k: float(spec.get(k, 1.0 if k == "traces_per_px" else 0.0)) for k in _MAP_KEYS}
    if not all(math.isfinite(v) for v in vals.values()):
        raise InvalidDataError(f"pixel map holds NaN/inf: {vals}")
    if not 0 < vals["s_per_px"] < 1e-6:
        raise InvalidDataError(f"pixel map s_per_px = {vals['s_per_px']!r} s is not a plausible row interval "
                               "(GPR rows are 1e-12..1e-6 s apart; give seconds, e.g. 1e-10)")
    if vals["traces_per_px"] <= 0:
        raise InvalidDataError(f"pixel map traces_per_px must be > 0, got {vals['traces_per_px']!r}")
    return PixelMap(**vals)


#: class names that other datasets use for gpr3d's target kinds (P-GPR's ``steel`` is rebar)
KIND_ALIASES = {"steel": "rebar", "rebars": "rebar", "bar": "rebar", "reinforcement": "rebar", "metal_pipe": "steel_pipe",
                "plastic_pipe": "pvc_pipe", "pvc": "pvc_pipe", "ppr": "pvc_pipe", "ppr_pipe": "pvc_pipe",
                "cavity": "void", "air_void": "void"}


def _kind(name) -> str:
    name = str(name).strip().lower().replace(" ", "_").replace("-", "_")
    name = KIND_ALIASES.get(name, name)
    return name if name in CATEGORIES else "target"


def _picture_survey(path: Path, pm: PixelMap, frequency_hz: float | None = None):
    from PIL import Image, UnidentifiedImageError

    from gpr3d.core.survey import Survey

    try:
        with Image.open(path) as im:
            grey = np.asarray(im.convert("L"), dtype=np.float32)
    except (UnidentifiedImageError, OSError) as exc:
        raise FormatError(path, f"not a readable picture ({exc})") from None
    if grey.shape[0] < 8 or grey.shape[1] < 2:
        raise FormatError(path, f"a {grey.shape[1]} x {grey.shape[0]} picture is too small for a B-scan")
    data = grey.T - float(grey.mean())  # one trace per column, one sample per row
    return Survey(data=data, dt_s=pm.s_per_px, frequency_hz=frequency_hz,
                  metadata={"format": "picture", "path": str(path),
                                                          "pixel_map": {k: getattr(pm, k) for k in _MAP_KEYS}})


def read_picture(path, pixel_map, *, frequency_hz: float | None = None):
    """A picture of a B-scan (PNG, JPG, ...; a screenshot) as a Survey: one trace per column, one sample per row.

    Parameters
    ----------
    path : str or Path
        The picture.
    pixel_map : str or dict
        Its time axis (``s_per_px`` at least; :func:`parse_pixel_map`).
    frequency_hz : float, optional
        The radar's centre frequency, when known.

    Returns
    -------
    Survey
        Grey levels less their mean, ``dt_s`` = ``s_per_px``; the map kept in ``metadata["pixel_map"]``.

    Raises
    ------
    FormatError
        Not a readable picture, or too small for a B-scan.
    InvalidDataError
        No or a wrong pixel map.
    """
    p = check_file(path)
    if pixel_map is None:
        raise InvalidDataError(f"{p.name} is a picture: give its time axis (--pixel-map s_per_px=SECONDS)")
    pm = parse_pixel_map(pixel_map)
    check_frequency(frequency_hz)
    return _picture_survey(p, pm, frequency_hz)


def check_frequency(frequency_hz) -> None:
    """Refuse an antenna frequency no GPR has (outside 1 MHz .. 100 GHz, or not a number); ``None`` passes."""
    if frequency_hz is None:
        return
    try:
        f = float(frequency_hz)
    except (TypeError, ValueError):
        raise InvalidDataError(f"frequency {frequency_hz!r} is not a number (Hz)") from None
    if not (math.isfinite(f) and 1e6 <= f <= 1e11):
        raise InvalidDataError(f"frequency {frequency_hz!r} Hz is not a GPR antenna's (1 MHz .. 100 GHz; give Hz, "
                               "e.g. 1.6e9)")


def _record_map(survey, image: dict, width, height) -> PixelMap:
    if image.get("gpr3d_pixel_map") is not None:
        return parse_pixel_map(image["gpr3d_pixel_map"])
    if image.get("row_s"):
        return PixelMap(s_per_px=float(image["row_s"]))
    if not width or not height or width < 2 or height < 2:
        raise InvalidDataError(f"image {image.get('file_name')!r}: no width/height to map its pixels onto the record")
    return PixelMap(traces_per_px=(survey.n_traces - 1) / (width - 1),
                    s_per_px=(survey.n_samples - 1) * survey.dt_s / (height - 1))


def _labels(survey, boxes_px, names, pm: PixelMap, where: str, *, tight: bool = False) -> dict:
    """Pixel boxes ``[x0, y0, x1, y1]`` -> labels in the record's traces and seconds.

    ``tight``: the boxes enclose the hyperbola's vertex and legs tightly (YOLO datasets
    such as P-GPR), so the apex is a tenth of the way down the box whatever the frequency.
    """
    t_end = (survey.n_samples - 1) * survey.dt_s
    f = survey.frequency_hz
    out = []
    for k, (px, name) in enumerate(zip(boxes_px, names)):
        px = [float(v) for v in px]
        if not all(math.isfinite(v) for v in px):
            raise InvalidDataError(f"{where}: box {k} holds NaN/inf: {px}")
        if px[2] <= px[0] or px[3] <= px[1]:
            raise InvalidDataError(f"{where}: box {k} has no area: {px} (x0 < x1 and y0 < y1 needed)")
        i0, t0, i1, t1 = pm.px_to_box(px)
        if i1 < 0 or i0 > survey.n_traces - 1 or t1 < 0 or t0 > t_end:
            raise InvalidDataError(f"{where}: box {k} lies outside the record ({survey.n_traces} traces, "
                                   f"{t_end * 1e9:.3g} ns): check the pixel map")
        i0, i1 = max(i0, 0.0), min(i1, survey.n_traces - 1.0)
        t0, t1 = max(t0, 0.0), min(t1, t_end)
        down = BOX_PAD_PERIODS / f if f and not tight else 0.1 * (t1 - t0)
        kind = _kind(name)
        out.append({"kind": kind, "category": CATEGORIES.index(kind) + 1 if kind in CATEGORIES else 0,
                    "box": [i0, t0, i1, t1], "apex_trace": 0.5 * (i0 + i1),
                    "apex_time_s": min(t0 + down, t1), "visible": True, "source_name": str(name)})
    return {"n_traces": survey.n_traces, "n_samples": survey.n_samples, "dt_s": survey.dt_s,
            "eps_r": survey.eps_r, "labels": out}


def _load(base: Path, file_name: str, image: dict, width, height, pixel_map, boxes_px, names, where):
    from gpr3d.io.registry import read

    if not file_name:
        raise InvalidDataError(f"{where}: the image names no file")
    p = Path(file_name)
    p = p if p.is_absolute() else base / p
    if not p.exists():
        raise FormatError(p, f"named by {where}, but no such file")
    if p.suffix.lower() in IMAGE_SUFFIXES:
        spec = image.get("gpr3d_pixel_map") or pixel_map
        if spec is None:
            raise InvalidDataError(f"{where}: {p.name} is a picture; give its time axis (a pixel map with s_per_px)")
        pm = parse_pixel_map(spec)
        survey = _picture_survey(p, pm)
        own = PixelMap(s_per_px=pm.s_per_px)  # the picture record: trace = column, time = row * s_per_px
        return survey, _labels(survey, boxes_px, names, own, where)
    survey = read(p)
    return survey, _labels(survey, boxes_px, names, _record_map(survey, image, width, height), where)


def _read_coco(path: Path, pixel_map):
    try:
        doc = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FormatError(path, f"not valid JSON ({exc})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("images"), list) \
            or not isinstance(doc.get("annotations"), list):
        raise FormatError(path, "not a COCO detection file (needs 'images' and 'annotations' lists)")
    cats = {c.get("id"): c.get("name", "target") for c in doc.get("categories", []) if isinstance(c, dict)}
    per_image: dict = {}
    for a in doc["annotations"]:
        if not isinstance(a, dict) or "image_id" not in a or "bbox" not in a:
            raise FormatError(path, f"annotation {a!r:.80} lacks image_id or bbox")
        bb = a["bbox"]
        if not isinstance(bb, list) or len(bb) != 4:
            raise FormatError(path, f"annotation {a.get('id')}: bbox must be [x, y, w, h], got {bb!r:.80}")
        x, y, w, h = (float(v) for v in bb)
        per_image.setdefault(a["image_id"], []).append(([x, y, x + w, y + h], cats.get(a.get("category_id"), "target")))
    records = []
    for im in doc["images"]:
        if not isinstance(im, dict) or "id" not in im:
            raise FormatError(path, f"image entry {im!r:.80} has no id")
        anns = per_image.get(im["id"], [])
        where = f"{path.name} image {im['id']}"
        records.append(_load(path.parent, im.get("file_name"), im, im.get("width"), im.get("height"), pixel_map,
                             [b for b, _ in anns], [n for _, n in anns], where))
    return records


def _read_voc(path: Path, pixel_map):
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise FormatError(path, f"not valid XML ({exc})") from None
    if root.tag != "annotation":
        raise FormatError(path, f"not a Pascal VOC file (root element <{root.tag}>, expected <annotation>)")

    def num(node, tag):
        el = node.find(tag)
        if el is None or el.text is None:
            raise FormatError(path, f"<{tag}> missing")
        try:
            return float(el.text)
        except ValueError:
            raise FormatError(path, f"<{tag}> = {el.text!r} is not a number") from None

    size = root.find("size")
    width = num(size, "width") if size is not None else None
    height = num(size, "height") if size is not None else None
    boxes, names = [], []
    for obj in root.findall("object"):
        bb = obj.find("bndbox")
        if bb is None:
            raise FormatError(path, "an <object> has no <bndbox>")
        # VOC pixels are 1-based and inclusive: to 0-based corners
        boxes.append([num(bb, "xmin") - 1, num(bb, "ymin") - 1, num(bb, "xmax"), num(bb, "ymax")])
        names.append((obj.findtext("name") or "target").strip())
    file_name = (root.findtext("filename") or "").strip()
    if not file_name or not (path.parent / file_name).exists():
        file_name = (root.findtext("path") or file_name).strip()
    extra = {}
    pm_el = root.find("gpr3d_pixel_map")
    if pm_el is not None:  # <gpr3d_pixel_map><s_per_px>1e-10</s_per_px>...</gpr3d_pixel_map>
        extra["gpr3d_pixel_map"] = {c.tag: num(pm_el, c.tag) for c in pm_el}
    return [_load(path.parent, file_name, {"file_name": file_name, **extra}, width, height, pixel_map, boxes, names,
                  path.name)]


def read_user_labels(path, *, pixel_map=None) -> list:
    """Labelled records ``[(Survey, labels dict), ...]`` from a COCO ``.json``, a VOC ``.xml``, or a folder of VOC files.

    ``pixel_map`` (``"s_per_px=...,t0_s=...,traces_per_px=...,trace0=..."`` or a dict)
    gives the time axis of pictures that carry none of their own.
    """
    p = Path(path)
    if p.is_dir():
        xmls = sorted(p.glob("*.xml"))
        if not xmls:
            raise FormatError(p, "folder holds no Pascal VOC .xml files")
        return [r for x in xmls for r in _read_voc(x, pixel_map)]
    p = check_file(p)
    if pixel_map is not None:
        parse_pixel_map(pixel_map)  # a wrong map fails now, before any file is read
    if p.suffix.lower() == ".json":
        return _read_coco(p, pixel_map)
    if p.suffix.lower() == ".xml":
        return _read_voc(p, pixel_map)
    raise FormatError(p, "labels must be COCO (.json), Pascal VOC (.xml) or a folder of VOC files")
