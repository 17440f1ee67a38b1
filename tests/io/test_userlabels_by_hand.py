"""Users' labels by hand: a small record and a small picture made here, every message in full, every field of
every label (pixels to traces and seconds worked out in the test)."""

import json

import numpy as np
import pytest
from PIL import Image

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.io.userlabels import parse_pixel_map, read_user_labels

DT = 1e-10


@pytest.fixture
def rec(tmp_path):
    """A record of 21 traces x 51 samples (t_end 5 ns), 1 GHz, eps 7."""
    s = Survey(data=np.random.default_rng(0).normal(size=(21, 51)).astype(np.float32), dt_s=DT, frequency_hz=1e9,
               eps_r=7.0)
    s.save(tmp_path / "r.h5")
    return s


def _coco(tmp_path, images, anns, cats=({"id": 3, "name": "Steel Pipe"},), name="c.json"):
    p = tmp_path / name
    p.write_text(json.dumps({"images": list(images), "annotations": list(anns), "categories": list(cats)}))
    return p


def test_coco_labels_by_hand(tmp_path, rec):
    # the image is 11 x 26 pixels over 21 traces x 51 samples: 2 traces and 2e-10 s per pixel
    p = _coco(tmp_path, [{"id": 5, "file_name": "r.h5", "width": 11, "height": 26}],
              [{"id": 1, "image_id": 5, "category_id": 3, "bbox": [1, 2, 3, 10]},
               {"id": 2, "image_id": 5, "category_id": 9, "bbox": [8, 20, 4, 10]}])  # past the right and bottom
    (s, lab), = read_user_labels(p)
    np.testing.assert_array_equal(s.data, rec.data)
    assert {k: lab[k] for k in ("n_traces", "n_samples", "dt_s", "eps_r")} == {"n_traces": 21, "n_samples": 51,
                                                                                "dt_s": DT, "eps_r": 7.0}
    a, b = lab["labels"]
    assert a["kind"] == "steel_pipe" and a["category"] == 2 and a["source_name"] == "Steel Pipe" and a["visible"]
    assert a["box"] == pytest.approx([2.0, 4e-10, 8.0, 24e-10], rel=1e-12, abs=1e-22)
    assert a["apex_trace"] == pytest.approx(5.0, rel=1e-12)
    assert a["apex_time_s"] == pytest.approx(4e-10 + 0.7e-9, rel=1e-12, abs=0)  # 0.7 periods below the top
    # unknown category: 'target', category 0; cut to the record (trace 20, 5 ns); apex capped at the bottom
    assert b["kind"] == "target" and b["category"] == 0 and b["source_name"] == "target"
    assert b["box"] == pytest.approx([16.0, 40e-10, 20.0, 50e-10], rel=1e-12, abs=1e-22)
    assert b["apex_trace"] == pytest.approx(18.0) and b["apex_time_s"] == pytest.approx(47e-10, rel=1e-12, abs=0)


def test_a_record_without_frequency_puts_the_apex_a_tenth_down_the_box(tmp_path):
    s = Survey(data=np.zeros((21, 51), np.float32) + 1, dt_s=DT)
    s.save(tmp_path / "n.h5")
    p = _coco(tmp_path, [{"id": 1, "file_name": "n.h5", "row_s": 2e-10}],  # row_s: the time axis, 1 trace per px
              [{"id": 1, "image_id": 1, "category_id": 3, "bbox": [2, 5, 4, 10]}])
    (_, lab), = read_user_labels(p)
    x = lab["labels"][0]
    assert x["box"] == pytest.approx([2.0, 10e-10, 6.0, 30e-10], rel=1e-12, abs=1e-22)
    assert x["apex_time_s"] == pytest.approx(10e-10 + 0.1 * 20e-10, rel=1e-12, abs=0)
    assert lab["eps_r"] is None


def test_a_picture_with_its_map_by_hand(tmp_path):
    pixels = np.tile(np.arange(12, dtype=np.uint8)[:, None] * 10, (1, 5))  # 5 columns x 12 rows
    Image.fromarray(pixels).save(tmp_path / "p.png")
    p = _coco(tmp_path, [{"id": 1, "file_name": "p.png", "gpr3d_pixel_map": {"s_per_px": 1e-10, "t0_s": 5e-10}}],
              [{"id": 1, "image_id": 1, "category_id": 3, "bbox": [1, 2, 2, 4]}])
    (s, lab), = read_user_labels(p)
    assert s.n_traces == 5 and s.n_samples == 12 and s.dt_s == 1e-10
    np.testing.assert_allclose(s.data, pixels.T.astype(np.float32) - pixels.mean(), rtol=0, atol=1e-5)
    assert s.metadata == {"format": "picture", "path": str(tmp_path / "p.png"),
                          "pixel_map": {"trace0": 0.0, "traces_per_px": 1.0, "t0_s": 5e-10, "s_per_px": 1e-10}}
    # the picture's own record: trace = column, time = row x s_per_px (its t0 describes the picture, not the boxes)
    assert lab["labels"][0]["box"] == pytest.approx([1.0, 2e-10, 3.0, 6e-10], rel=1e-12, abs=1e-22)


@pytest.mark.parametrize("spec, message", [
    ("s_per_px=1e-10,x", "pixel map 's_per_px=1e-10,x': expected key=value pairs, got 'x'"),
    ("s_per_px=fast", "pixel map 's_per_px=fast': s_per_px = 'fast' is not a number"),
    (3, "pixel map must be key=value pairs or an object, got int"),
    ({"s_per_px": 1e-10, "zoom": 2, "a": 1}, "pixel map: unknown key(s) ['a', 'zoom'] (use trace0, traces_per_px, "
                                             "t0_s, s_per_px)"),
    ({"t0_s": 0.0}, "pixel map needs s_per_px (seconds per pixel row)"),
    ({"s_per_px": float("nan")}, "pixel map holds NaN/inf: {'trace0': 0.0, 'traces_per_px': 1.0, 't0_s': 0.0, "
                                 "'s_per_px': nan}"),
    ({"s_per_px": 0.0}, "pixel map s_per_px = 0.0 s is not a plausible row interval (GPR rows are 1e-12..1e-6 s "
                        "apart; give seconds, e.g. 1e-10)"),
    ({"s_per_px": 1e-6}, "pixel map s_per_px = 1e-06 s is not a plausible row interval (GPR rows are 1e-12..1e-6 s "
                         "apart; give seconds, e.g. 1e-10)"),
    ({"s_per_px": 1e-10, "traces_per_px": 0}, "pixel map traces_per_px must be > 0, got 0.0"),
])
def test_pixel_map_messages_in_full(spec, message):
    with pytest.raises(InvalidDataError) as err:
        parse_pixel_map(spec)
    assert str(err.value) == message


def test_pixel_maps_as_text_with_spaces_and_an_equals_sign_in_no_value():
    pm = parse_pixel_map(" s_per_px = 2e-10 , trace0=3,, t0_s=1e-9 ")
    assert (pm.s_per_px, pm.trace0, pm.t0_s, pm.traces_per_px) == (2e-10, 3.0, 1e-9, 1.0)
    with pytest.raises(InvalidDataError, match=r"^pixel map 's_per_px=1e-10=2': s_per_px = '1e-10=2' is not a "):
        parse_pixel_map("s_per_px=1e-10=2")
    assert parse_pixel_map(pm) is pm


@pytest.mark.parametrize("doc, message", [
    ("{", "c.json: not valid JSON (Expecting property name enclosed in double quotes: line 1 column 2 (char 1))"),
    ("[]", "c.json: not a COCO detection file (needs 'images' and 'annotations' lists)"),
    ('{"images": []}', "c.json: not a COCO detection file (needs 'images' and 'annotations' lists)"),
    ('{"annotations": [], "images": {}}', "c.json: not a COCO detection file (needs 'images' and 'annotations' lists)"),
    ('{"images": [], "annotations": [{"image_id": 1}]}', "c.json: annotation {'image_id': 1} lacks image_id or bbox"),
    ('{"images": [], "annotations": [{"bbox": [1, 2, 3, 4]}]}',
     "c.json: annotation {'bbox': [1, 2, 3, 4]} lacks image_id or bbox"),
    ('{"images": [], "annotations": [3]}', "c.json: annotation 3 lacks image_id or bbox"),
    ('{"images": [], "annotations": [{"id": 7, "image_id": 1, "bbox": [1, 2, 3]}]}',
     "c.json: annotation 7: bbox must be [x, y, w, h], got [1, 2, 3]"),
    ('{"images": [{"file_name": "r.h5"}], "annotations": []}', "c.json: image entry {'file_name': 'r.h5'} has no id"),
    ('{"images": [5], "annotations": []}', "c.json: image entry 5 has no id"),
    ('{"images": [{"id": 4}], "annotations": []}', "c.json image 4: the image names no file"),
    ('{"images": [{"id": 4, "file_name": "none.h5"}], "annotations": []}',
     "none.h5: named by c.json image 4, but no such file"),
    ('{"images": [{"id": 4, "file_name": "r.h5", "width": 1, "height": 20}], "annotations": []}',
     "image 'r.h5': no width/height to map its pixels onto the record"),
    ('{"images": [{"id": 4, "file_name": "r.h5", "width": 20, "height": 1}], "annotations": []}',
     "image 'r.h5': no width/height to map its pixels onto the record"),
    ('{"images": [{"id": 4, "file_name": "r.h5", "width": 11}], "annotations": []}',
     "image 'r.h5': no width/height to map its pixels onto the record"),
])
def test_coco_messages_in_full(tmp_path, rec, doc, message):
    (tmp_path / "c.json").write_text(doc)
    with pytest.raises((FormatError, InvalidDataError)) as err:
        read_user_labels(tmp_path / "c.json")
    assert str(err.value) == message


@pytest.mark.parametrize("bbox, message", [
    ([1, 2, 0, 3], "c.json image 4: box 0 has no area: [1.0, 2.0, 1.0, 5.0] (x0 < x1 and y0 < y1 needed)"),
    ([1, 2, 3, 0], "c.json image 4: box 0 has no area: [1.0, 2.0, 4.0, 2.0] (x0 < x1 and y0 < y1 needed)"),
    ([1, 2, 3, float("nan")], "c.json image 4: box 0 holds NaN/inf: [1.0, 2.0, 4.0, nan]"),
    ([-9, 2, 3, 4], "c.json image 4: box 0 lies outside the record (21 traces, 5 ns): check the pixel map"),
    ([11, 2, 3, 4], "c.json image 4: box 0 lies outside the record (21 traces, 5 ns): check the pixel map"),
    ([1, -9, 3, 4], "c.json image 4: box 0 lies outside the record (21 traces, 5 ns): check the pixel map"),
    ([1, 26, 3, 4], "c.json image 4: box 0 lies outside the record (21 traces, 5 ns): check the pixel map"),
])
def test_box_messages_in_full(tmp_path, rec, bbox, message):
    p = _coco(tmp_path, [{"id": 4, "file_name": "r.h5", "width": 11, "height": 26}],
              [{"id": 1, "image_id": 4, "category_id": 3, "bbox": bbox}])
    with pytest.raises(InvalidDataError) as err:
        read_user_labels(p)
    assert str(err.value) == message


def test_boxes_touching_the_record_s_edges_are_inside(tmp_path, rec):
    p = _coco(tmp_path, [{"id": 4, "file_name": "r.h5", "width": 11, "height": 26}],
              [{"id": 1, "image_id": 4, "bbox": [-3, -3, 3, 3]}, {"id": 2, "image_id": 4, "bbox": [10, 25, 3, 3]}])
    (_, lab), = read_user_labels(p)
    assert [x["box"] for x in lab["labels"]] == [pytest.approx([0, 0, 0, 0]), pytest.approx([20, 5e-9, 20, 5e-9])]


def _voc(tmp_path, body, name="v.xml"):
    p = tmp_path / name
    p.write_text(f"<annotation>{body}</annotation>")
    return p


@pytest.mark.parametrize("body, message", [
    ("<filename>r.h5</filename><object><name>x</name></object>", "v.xml: an <object> has no <bndbox>"),
    ("<filename>r.h5</filename><object><bndbox><xmin>1</xmin><ymin>1</ymin><xmax>2</xmax></bndbox></object>",
     "v.xml: <ymax> missing"),
    ("<filename>r.h5</filename><object><bndbox><xmin>1</xmin><ymin>1</ymin><xmax>2</xmax><ymax>z</ymax></bndbox>"
     "</object>", "v.xml: <ymax> = 'z' is not a number"),
    ("<filename>r.h5</filename><size><width/></size>", "v.xml: <width> missing"),
])
def test_voc_messages_in_full(tmp_path, rec, body, message):
    with pytest.raises(FormatError) as err:
        read_user_labels(_voc(tmp_path, body))
    assert str(err.value) == message


def test_voc_by_hand_with_its_own_map_and_a_path_when_the_file_name_is_elsewhere(tmp_path, rec):
    body = ("<filename>elsewhere.h5</filename><path>r.h5</path><size><width>11</width><height>26</height></size>"
            "<object><name> Rebar </name><bndbox><xmin>2</xmin><ymin>3</ymin><xmax>4</xmax><ymax>12</ymax></bndbox>"
            "</object><object><bndbox><xmin>1</xmin><ymin>1</ymin><xmax>11</xmax><ymax>26</ymax></bndbox></object>")
    (s, lab), = read_user_labels(_voc(tmp_path, body))
    a, b = lab["labels"]
    # VOC pixels are 1-based, inclusive: [1, 2, 4, 12] in 0-based corners; 2 traces and 2e-10 s per pixel
    assert a["kind"] == "rebar" and a["source_name"] == "Rebar" and a["category"] == 1
    assert a["box"] == pytest.approx([2.0, 4e-10, 8.0, 24e-10], rel=1e-12, abs=1e-22)
    assert b["kind"] == "target" and b["box"] == pytest.approx([0.0, 0.0, 20.0, 50e-10], rel=1e-12, abs=1e-22)
    own = ("<filename>r.h5</filename><gpr3d_pixel_map><s_per_px>1e-10</s_per_px><traces_per_px>2</traces_per_px>"
           "</gpr3d_pixel_map><object><bndbox><xmin>2</xmin><ymin>3</ymin><xmax>4</xmax><ymax>12</ymax></bndbox>"
           "</object>")
    (_, lab), = read_user_labels(_voc(tmp_path, own, "w.xml"))
    assert lab["labels"][0]["box"] == pytest.approx([2.0, 2e-10, 8.0, 12e-10], rel=1e-12, abs=1e-22)


def _refusal(path, **kw) -> str:
    with pytest.raises(FormatError) as err:
        read_user_labels(path, **kw)
    return str(err.value)


def test_what_is_not_labels_is_named(tmp_path, rec):
    (tmp_path / "empty").mkdir()
    assert _refusal(tmp_path / "empty") == "empty: folder holds no Pascal VOC .xml files"
    (tmp_path / "l.txt").write_text("x")
    assert _refusal(tmp_path / "l.txt") == ("l.txt: labels must be COCO (.json), Pascal VOC (.xml) or a folder of "
                                            "VOC files")
    (tmp_path / "x.xml").write_text("<root/>")
    assert _refusal(tmp_path / "x.xml") == "x.xml: not a Pascal VOC file (root element <root>, expected <annotation>)"
    (tmp_path / "b.xml").write_text("<annotation>")
    assert _refusal(tmp_path / "b.xml").startswith("b.xml: not valid XML (no element found")
    (tmp_path / "q.png").write_bytes(b"not a png")
    p = _coco(tmp_path, [{"id": 1, "file_name": "q.png"}], [], name="q.json")
    assert _refusal(p, pixel_map="s_per_px=1e-10").startswith("q.png: not a readable picture (cannot identify image")


@pytest.mark.parametrize("shape, message", [((7, 4), "s.png: a 4 x 7 picture is too small for a B-scan"),
                                            ((8, 1), "s.png: a 1 x 8 picture is too small for a B-scan"),
                                            ((8, 2), None)])  # 2 x 8: just big enough
def test_pictures_too_small_for_a_bscan(tmp_path, shape, message):
    Image.fromarray(np.zeros(shape, np.uint8)).save(tmp_path / "s.png")
    p = _coco(tmp_path, [{"id": 1, "file_name": "s.png"}], [], name="s.json")
    if message:
        assert _refusal(p, pixel_map="s_per_px=1e-10") == message
    else:
        assert read_user_labels(p, pixel_map="s_per_px=1e-10")[0][0].n_traces == 2


def test_voc_folders_pass_the_pixel_map_on(tmp_path):
    Image.fromarray(np.tile(np.arange(10, dtype=np.uint8)[:, None], (1, 4))).save(tmp_path / "p.png")
    (tmp_path / "labels").mkdir()
    _voc(tmp_path / "labels", "<filename>../p.png</filename><object><bndbox><xmin>1</xmin><ymin>1</ymin>"
                              "<xmax>2</xmax><ymax>4</ymax></bndbox></object>", "a.xml")
    (s, lab), = read_user_labels(tmp_path / "labels", pixel_map="s_per_px=3e-10")
    assert s.dt_s == 3e-10 and lab["labels"][0]["box"] == pytest.approx([0, 0, 2, 12e-10], rel=1e-12, abs=1e-22)
    (s, _), = read_user_labels(tmp_path / "labels" / "a.xml", pixel_map="s_per_px=3e-10")
    assert s.dt_s == 3e-10
