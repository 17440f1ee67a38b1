"""One door to labelled B-scans, whatever their format: YOLO, COCO or Pascal VOC.

:func:`read_labelled` looks at what ``path`` is (a YOLO ``data.yaml`` or a folder with
``images/`` and ``labels/``; a COCO ``.json``; a VOC ``.xml`` or a folder of them) and
reads it with :func:`gpr3d.io.yolo.read_yolo` or :func:`gpr3d.io.userlabels.read_user_labels`.
"""

from __future__ import annotations

from gpr3d.io import userlabels
from gpr3d.io.coco import CATEGORIES
from gpr3d.io.yolo import is_yolo, parse_kinds, read_yolo

__all__ = ["read_labelled"]


def read_labelled(path, *, pixel_map=None, split: str = "train", names=None, kinds=None,
                  frequency_hz: float | None = None, pattern: str | None = None) -> list:
    """Labelled records ``[(Survey, labels dict), ...]`` from any supported label format.

    Parameters
    ----------
    path : str or Path
        YOLO dataset (``data.yaml`` or a folder with ``images/``), COCO ``.json``, VOC ``.xml`` or a folder of them.
    pixel_map : str or dict, optional
        The time axis of pictures (``s_per_px=...``); required for YOLO datasets.
    kinds : str or dict, optional
        Class (or COCO/VOC category) name -> target kind, ``"hyperbola=rebar"`` (:func:`gpr3d.io.yolo.parse_kinds`).
    split, names, frequency_hz, pattern
        For YOLO datasets: see :func:`gpr3d.io.yolo.read_yolo`.

    Returns
    -------
    list of (Survey, dict)
        The records with their labels in traces and seconds.

    Raises
    ------
    FormatError
        The labels or a file they name cannot be read (the message names it).
    InvalidDataError
        A wrong pixel map, split, class name or kind.
    """
    if is_yolo(path):
        return read_yolo(path, split=split, names=names, kinds=kinds, pixel_map=pixel_map, frequency_hz=frequency_hz,
                         pattern=pattern)
    records = userlabels.read_user_labels(path, pixel_map=pixel_map)  # looked up now (tests stand in for it)
    mapping = parse_kinds(kinds)
    if mapping:  # COCO/VOC category names mapped onto kinds as YOLO class names are
        for _, labels in records:
            for lab in labels["labels"]:
                kind = mapping.get(str(lab.get("source_name", "")).strip().lower())
                if kind:
                    lab["kind"], lab["category"] = kind, CATEGORIES.index(kind) + 1
    return records
