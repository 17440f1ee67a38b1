"""YOLO datasets by hand: small pictures and label files made here, every box worked out in traces and seconds in
the test; data.yaml forms; every message; and P-GPR's real splits counted against their own label files."""

import numpy as np
import pytest
from PIL import Image

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.io.labelled import read_labelled
from gpr3d.io.yolo import is_yolo, parse_kinds, read_yolo, records_summary
from tests.conftest import real_file

S = 2e-10  # seconds per row
PM = f"s_per_px={S}"


def _picture(path, w=40, h=20, seed=0):
    path.parent.mkdir(parents=True, exist_ok=True)
    grey = np.random.default_rng(seed).integers(0, 256, size=(h, w)).astype(np.uint8)
    Image.fromarray(grey).save(path)
    return grey


def _dataset(root, labels: dict, sizes=None):
    """root/images/NAME.png (+ root/labels/NAME.txt when its text is not None)."""
    for name, text in labels.items():
        w, h = (sizes or {}).get(name, (40, 20))
        _picture(root / "images" / f"{name}.png", w, h)
        if text is not None:
            (root / "labels").mkdir(parents=True, exist_ok=True)
            (root / "labels" / f"{name}.txt").write_text(text)
    return root


def test_a_folder_by_hand(tmp_path):
    root = _dataset(tmp_path / "ds", {"a": "0 0.5 0.25 0.5 0.5\n\n1 0.125 0.5 0.25 1.0\n", "b": None})
    grey = np.asarray(Image.open(root / "images" / "a.png").convert("L"), dtype=np.float32)
    recs = read_yolo(root, names=["steel", "pipe"], kinds="pipe=pvc_pipe", pixel_map=PM, frequency_hz=1.6e9)
    assert [r[1]["image"] for r in recs] == [str(root / "images" / "a.png"), str(root / "images" / "b.png")]
    s, lab = recs[0]
    np.testing.assert_allclose(s.data, grey.T - grey.mean(), rtol=0, atol=1e-4)  # one trace per column
    assert (s.dt_s, s.frequency_hz, s.n_traces, s.n_samples) == (S, 1.6e9, 40, 20)
    assert lab["image_size"] == [40, 20]
    a, b = lab["labels"]
    # box 0: columns 10..30 and rows 0..10 as pixel corners; a column's centre is its trace: traces 9.5..29.5
    assert (a["kind"], a["source_name"], a["category"]) == ("rebar", "steel", 1)  # steel is rebar
    assert a["box"] == pytest.approx([9.5, 0.0, 29.5, 9.5 * S], rel=1e-12, abs=1e-22)  # row -0.5 clipped to 0
    assert a["apex_trace"] == pytest.approx(19.5)
    assert a["apex_time_s"] == pytest.approx(0.1 * 9.5 * S, rel=1e-12)  # a tight box: a tenth down, not 0.7 periods
    # box 1: columns 0..10, rows 0..20: cut to the record's first trace and last sample
    assert (b["kind"], b["source_name"], b["category"]) == ("pvc_pipe", "pipe", 3)
    assert b["box"] == pytest.approx([0.0, 0.0, 9.5, 19 * S], rel=1e-12, abs=1e-22)
    assert recs[1][1]["labels"] == []  # no label file: a picture with no targets
    assert records_summary(recs) == {"records": 2, "boxes": 2, "by_kind": {"pvc_pipe": 1, "rebar": 1}}
    only = read_yolo(root, pixel_map=PM, pattern="b*")
    assert [r[1]["image"] for r in only] == [str(root / "images" / "b.png")]
    with pytest.raises(FormatError) as err:
        read_yolo(root, pixel_map=PM, pattern="AIR_*")
    assert str(err.value) == "ds: a YOLO dataset with no pictures (train, AIR_*)"


def test_names_from_a_data_yaml_as_a_list_or_a_mapping_and_splits(tmp_path):
    _dataset(tmp_path / "d" / "train", {"x": "1 0.5 0.5 0.5 0.5\n"})
    _dataset(tmp_path / "d" / "valid", {"y": "0 0.5 0.5 0.25 0.5\n", "z": "0 0.25 0.5 0.25 0.5\n"})
    (tmp_path / "d" / "list.txt").write_text("valid/images/z.png\n\n")
    (tmp_path / "d" / "data.yaml").write_text("path: .\ntrain: train/images\nval: [valid/images]\n"
                                              "test: list.txt\nnames: {0: Rebar, 1: void}\n")
    train = read_yolo(tmp_path / "d", pixel_map=PM)
    assert [lab["kind"] for _, r in train for lab in r["labels"]] == ["void"]
    val = read_yolo(tmp_path / "d" / "data.yaml", split="val", pixel_map=PM)
    assert [(lab["kind"], lab["source_name"]) for _, r in val for lab in r["labels"]] == [("rebar", "Rebar")] * 2
    test = read_yolo(tmp_path / "d", split="test", pixel_map=PM, names=["tank"])
    assert [Path_name(r) for r in test] == ["z.png"] and test[0][1]["labels"][0]["kind"] == "tank"
    (tmp_path / "d" / "data.yaml").write_text("train: train/images\nnames: [a, b]\n")
    assert [lab["kind"] for _, r in read_yolo(tmp_path / "d", pixel_map=PM) for lab in r["labels"]] == ["target"]
    assert is_yolo(tmp_path / "d") and is_yolo(tmp_path / "d" / "data.yaml") and not is_yolo(tmp_path / "d" / "valid"
                                                                                               / "images")
    # read_labelled sends YOLO here and the rest to the COCO/VOC reader
    assert [r[1]["image"] for r in read_labelled(tmp_path / "d", pixel_map=PM)] == [r[1]["image"] for r in train]


def Path_name(rec):
    return rec[1]["image"].rsplit("/", 1)[-1]


def test_a_polygon_line_counts_as_its_box(tmp_path):
    root = _dataset(tmp_path, {"p": "0 0.25 0.5 0.75 0.25 0.5 1.0\n"})
    (_, lab), = read_yolo(root, pixel_map=PM)
    assert lab["labels"][0]["box"] == pytest.approx([9.5, 4.5 * S, 29.5, 19 * S], rel=1e-12)


@pytest.mark.parametrize("text, names, message", [
    ("0 0.5 0.5 0.2\n", None, "line 1: 4 numbers; a box line is 'class cx cy w h'"),
    ("0 0.5 0.5 0.2 0.2 0.1\n", None, "line 1: 6 numbers; a box line is 'class cx cy w h'"),
    ("0 0.5 nan 0.2 0.2\n", None, "line 1: holds NaN/inf"),
    ("0 0.5 0.5 0.2 0.2\nsteel 0.5 0.5 0.2 0.2\n", None, "line 2: 'steel 0.5 0.5 0.2 0.2' is not numbers (class cx cy w h)"),
    ("2 0.5 0.5 0.2 0.2\n", ["a", "b"], "line 1: class 2 is not a class id (classes 0..1)"),
    ("0.5 0.5 0.5 0.2 0.2\n", None, "line 1: class 0.5 is not a class id"),
    ("-1 0.5 0.5 0.2 0.2\n", None, "line 1: class -1 is not a class id"),
    ("0 50 10 20 8\n", None, "line 1: the box reaches outside 0..1 (0 50 10 20 8): YOLO boxes are normalised by the "
                             "picture's size"),
    ("0 0.5 0.5 0 0.2\n", None, "line 1: the box has no area"),
])
def test_every_wrong_label_line_is_named(tmp_path, text, names, message):
    root = _dataset(tmp_path, {"a": text})
    with pytest.raises(FormatError) as err:
        read_yolo(root, pixel_map=PM, names=names)
    assert str(err.value) == f"a.txt: {message}"


def test_every_wrong_dataset_or_argument_is_named(tmp_path):
    root = _dataset(tmp_path / "ds", {"a": "0 0.5 0.5 0.2 0.2\n"})

    def msg(exc, *a, **k):
        with pytest.raises(exc) as err:
            read_yolo(*a, **k)
        return str(err.value)

    assert msg(InvalidDataError, root) == (f"{root}: YOLO pictures carry no time axis; give a pixel map with s_per_px "
                                           "(e.g. --pixel-map s_per_px=3.125e-11 for 8 ns over 256 rows)")
    assert msg(InvalidDataError, root, pixel_map=PM, split="dev") == "split must be one of train, val, test, got 'dev'"
    assert msg(InvalidDataError, root, pixel_map=PM, kinds="pipe=tube") == \
        "kinds: pipe=tube: 'tube' is not a target kind (rebar, steel_pipe, pvc_pipe, void, tank)"
    assert msg(InvalidDataError, root, pixel_map=PM, frequency_hz=5.0) == \
        "frequency 5.0 Hz is not a GPR antenna's (1 MHz .. 100 GHz; give Hz, e.g. 1.6e9)"
    assert msg(FormatError, tmp_path / "nosuch", pixel_map=PM) == "nosuch: no such file or folder"
    (tmp_path / "empty").mkdir()
    assert msg(FormatError, tmp_path / "empty", pixel_map=PM) == \
        "empty: not a YOLO dataset: no data.yaml and no images/ folder"
    (tmp_path / "e2" / "images").mkdir(parents=True)
    assert msg(FormatError, tmp_path / "e2", pixel_map=PM) == "e2: a YOLO dataset with no pictures (train)"
    (root / "data.yaml").write_text("train: images\nnames: [a]\n")
    assert msg(FormatError, root, pixel_map=PM, split="val") == "data.yaml: names no 'val' split (has train)"
    (root / "data.yaml").write_text("train: nowhere\n")
    assert msg(FormatError, root, pixel_map=PM) == \
        f"data.yaml: split entry 'nowhere': no such folder, list file or picture ({root / 'nowhere'})"
    (root / "data.yaml").write_text("train: [unclosed\n")
    assert msg(FormatError, root, pixel_map=PM).startswith("data.yaml: not valid YAML (")
    (root / "data.yaml").write_text("- a list\n")
    assert msg(FormatError, root, pixel_map=PM) == \
        "data.yaml: not a YOLO data file (expected a mapping with train/val and names)"
    (root / "data.yaml").write_text("train: images\nnames: {0: a, 2: b}\n")
    assert msg(FormatError, root, pixel_map=PM) == "data.yaml: names: class ids must run 0..1, got [0, 2]"
    (root / "data.yaml").write_text("train: images\nnames: {x: a}\n")
    assert msg(FormatError, root, pixel_map=PM) == "data.yaml: names: class ids must be integers, got ['x']"
    (root / "list.txt").write_text("images/gone.png\n")
    (root / "data.yaml").write_text("train: list.txt\n")
    assert msg(FormatError, root, pixel_map=PM) == "gone.png: named by the dataset, but no such picture"


@pytest.mark.parametrize("spec, message", [
    ("pipe", "kinds 'pipe': expected name=kind pairs, got 'pipe'"),
    ("=rebar", "kinds '=rebar': expected name=kind pairs, got '=rebar'"),
    (["a"], "kinds must be name=kind pairs or an object, got list"),
])
def test_wrong_kind_maps_are_named(spec, message):
    with pytest.raises(InvalidDataError) as err:
        parse_kinds(spec)
    assert str(err.value) == message


def test_kind_maps_are_read_case_blind():
    assert parse_kinds(" Pipe = pvc_pipe , steel=steel_pipe") == {"pipe": "pvc_pipe", "steel": "steel_pipe"}
    assert parse_kinds(None) == {} and parse_kinds({"X": "void"}) == {"x": "void"}


@pytest.mark.parametrize("split", ["train", "val"])
def test_pgpr_splits_read_as_their_label_files_say(split):
    folder = real_file(f"pgpr_1600MHz/{split}")
    recs = read_yolo(folder, names=["steel", "pipe"], kinds="pipe=pvc_pipe", pixel_map="s_per_px=3.125e-11",
                     frequency_hz=1.6e9)
    lines = {p.stem: [ln.split() for ln in p.read_text().splitlines() if ln.strip()]
             for p in (folder / "labels").glob("*.txt")}
    assert len(recs) == len(list((folder / "images").glob("*.png")))
    for survey, lab in recs:
        name = lab["image"].rsplit("/", 1)[-1][:-4]
        want = lines.get(name, [])
        assert survey.n_samples == 256 and survey.dt_s == 3.125e-11
        assert [x["kind"] for x in lab["labels"]] == [{"0": "rebar", "1": "pvc_pipe"}[w[0]] for w in want]
        w_px = survey.n_traces
        for x, w in zip(lab["labels"], want):
            cx, cy, bw, bh = (float(v) for v in w[1:])
            assert x["box"][0] == pytest.approx(max((cx - bw / 2) * w_px - 0.5, 0.0), abs=1e-6)
            assert x["box"][2] == pytest.approx(min((cx + bw / 2) * w_px - 0.5, w_px - 1.0), abs=1e-6)
            assert x["box"][3] == pytest.approx(min((cy + bh / 2) * 256 - 0.5, 255) * 3.125e-11, rel=1e-9)
