"""read_labelled by hand: which reader each kind of path goes to, with what, and the kind mapping it applies to COCO
and VOC category names (the readers themselves are tested in test_yolo.py and test_userlabels*.py)."""

import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.io import labelled, userlabels
from gpr3d.io.coco import CATEGORIES
from tests.io.test_yolo import PM, _dataset


def test_a_yolo_folder_goes_to_read_yolo_with_every_argument(tmp_path, monkeypatch):
    root = _dataset(tmp_path / "ds", {"a": "0 0.5 0.5 0.5 0.5\n"})
    seen = {}

    def fake_yolo(path, **kw):
        seen.update(kw, path=path)
        return ["yolo"]

    monkeypatch.setattr(labelled, "read_yolo", fake_yolo)
    monkeypatch.setattr(userlabels, "read_user_labels", lambda *a, **k: pytest.fail("not a COCO/VOC path"))
    out = labelled.read_labelled(root, pixel_map=PM, split="val", names=["steel"], kinds="steel=rebar",
                                 frequency_hz=1.6e9, pattern="a*")
    assert out == ["yolo"]
    assert seen == {"path": root, "split": "val", "names": ["steel"], "kinds": "steel=rebar", "pixel_map": PM,
                    "frequency_hz": 1.6e9, "pattern": "a*"}
    seen.clear()
    labelled.read_labelled(root, pixel_map=PM)  # the defaults
    assert seen == {"path": root, "split": "train", "names": None, "kinds": None, "pixel_map": PM,
                    "frequency_hz": None, "pattern": None}


def _records():
    return [(None, {"labels": [{"kind": "target", "category": 9, "source_name": " Pipe "},
                               {"kind": "target", "category": 9, "source_name": "stone"},
                               {"kind": "target", "category": 9}]}),
            (None, {"labels": [{"kind": "target", "category": 9, "source_name": "STEEL"}]})]


def test_coco_and_voc_names_are_mapped_onto_kinds(tmp_path, monkeypatch):
    seen = {}

    def fake(path, pixel_map=None):
        seen.update(path=path, pixel_map=pixel_map)
        return _records()

    monkeypatch.setattr(userlabels, "read_user_labels", fake)
    monkeypatch.setattr(labelled, "read_yolo", lambda *a, **k: pytest.fail("not a YOLO path"))
    p = tmp_path / "labels.json"
    p.write_text("{}")
    (a, b) = labelled.read_labelled(p, pixel_map=PM, kinds="pipe=pvc_pipe,steel=rebar")
    assert seen == {"path": p, "pixel_map": PM}
    pipe, stone, unnamed = a[1]["labels"]
    # names compared without case or surrounding spaces; the category follows the kind (COCO ids 1..5)
    assert (pipe["kind"], pipe["category"]) == ("pvc_pipe", CATEGORIES.index("pvc_pipe") + 1) == ("pvc_pipe", 3)
    assert (stone["kind"], stone["category"]) == ("target", 9) and (unnamed["kind"], unnamed["category"]) == ("target", 9)
    assert (b[1]["labels"][0]["kind"], b[1]["labels"][0]["category"]) == ("rebar", 1)
    # a label without a name is never mapped, whatever the classes are called
    (a, _) = labelled.read_labelled(p, pixel_map=PM, kinds="none=void,xxxx=void,pipe=pvc_pipe")
    assert (a[1]["labels"][2]["kind"], a[1]["labels"][2]["category"]) == ("target", 9)
    # without a mapping the records are the reader's as they came
    assert labelled.read_labelled(p, pixel_map=PM) == _records()
    with pytest.raises(InvalidDataError):
        labelled.read_labelled(p, pixel_map=PM, kinds="pipe=gravel")
