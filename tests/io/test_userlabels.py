"""Users' own labels: COCO and Pascal VOC over radar files and pictures, mapped back to traces and seconds."""

import json

import numpy as np
import pytest
from PIL import Image

from gpr3d.core.errors import GPR3DError
from gpr3d.io.coco import PixelMap
from gpr3d.io.userlabels import parse_pixel_map, read_user_labels
from gpr3d.simulation.surveys import survey_sample


@pytest.fixture(scope="module")
def records():
    return [survey_sample(777, i) for i in (0, 1)]


def _visible(lab):
    return [x for x in lab["labels"] if x["visible"]]


def _write_coco(tmp_path, records, *, height=None, name="coco.json"):
    """COCO over gpr3d .h5 files; pixels span the whole record (width x height) unless export-style."""
    images, anns = [], []
    for k, (s, lab) in enumerate(records):
        f = tmp_path / f"rec{k}.h5"
        s.save(f)
        h = height or s.n_samples
        pm = PixelMap(traces_per_px=(s.n_traces - 1) / (s.n_traces - 1), s_per_px=(s.n_samples - 1) * s.dt_s / (h - 1))
        images.append({"id": k + 10, "file_name": f.name, "width": s.n_traces, "height": h})
        for x in _visible(lab):
            x0, y0, x1, y1 = pm.box_to_px(x["box"])
            anns.append({"id": len(anns) + 1, "image_id": k + 10, "category_id": 2, "bbox": [x0, y0, x1 - x0, y1 - y0]})
    path = tmp_path / name
    path.write_text(json.dumps({"images": images, "annotations": anns,
                                "categories": [{"id": 2, "name": "steel_pipe"}]}))
    return path


def test_coco_over_radar_files_gives_the_boxes_back(tmp_path, records):
    got = read_user_labels(_write_coco(tmp_path, records, height=300))
    assert len(got) == 2
    for (s, lab), (g, glab) in zip(records, got):
        np.testing.assert_allclose(g.data, s.data, rtol=1e-6)
        want = np.array([x["box"] for x in _visible(lab)])
        have = np.array([x["box"] for x in glab["labels"]])
        assert have.shape == want.shape and len(want) > 0
        np.testing.assert_allclose(have[:, [0, 2]], want[:, [0, 2]], atol=1e-6)
        np.testing.assert_allclose(have[:, [1, 3]], want[:, [1, 3]], atol=1e-12)
        assert {x["kind"] for x in glab["labels"]} == {"steel_pipe"}
        for x in glab["labels"]:  # the apex: centre trace, 0.7 periods below the top
            assert x["apex_trace"] == pytest.approx(0.5 * (x["box"][0] + x["box"][2]))
            assert x["apex_time_s"] == pytest.approx(min(x["box"][1] + 0.7 / s.frequency_hz, x["box"][3]), rel=1e-9, abs=0)


def test_voc_files_and_folder_agree_with_coco(tmp_path, records):
    s, lab = records[0]
    s.save(tmp_path / "a.h5")
    h = 200
    pm = PixelMap(s_per_px=(s.n_samples - 1) * s.dt_s / (h - 1))
    objs = ""
    for x in _visible(lab):
        x0, y0, x1, y1 = pm.box_to_px(x["box"])
        objs += (f"<object><name>rebar</name><bndbox><xmin>{x0 + 1}</xmin><ymin>{y0 + 1}</ymin>"
                 f"<xmax>{x1}</xmax><ymax>{y1}</ymax></bndbox></object>")
    (tmp_path / "a.xml").write_text(f"<annotation><filename>a.h5</filename><size><width>{s.n_traces}</width>"
                                    f"<height>{h}</height><depth>3</depth></size>{objs}</annotation>")
    one = read_user_labels(tmp_path / "a.xml")
    folder = read_user_labels(tmp_path)
    assert len(one) == len(folder) == 1
    want = np.array([x["box"] for x in _visible(lab)])
    for got in (one, folder):
        have = np.array([x["box"] for x in got[0][1]["labels"]])
        np.testing.assert_allclose(have[:, [0, 2]], want[:, [0, 2]], atol=1e-6)
        np.testing.assert_allclose(have[:, [1, 3]], want[:, [1, 3]], atol=1e-12)
        assert {x["kind"] for x in got[0][1]["labels"]} == {"rebar"}


def test_a_screenshot_with_a_pixel_map_becomes_a_record(tmp_path, records):
    s, lab = records[1]
    d = s.dewow().remove_background().data
    grey = np.clip(128 + 127 * d / np.abs(d).max(), 0, 255).astype(np.uint8).T  # rows = samples, cols = traces
    Image.fromarray(grey).save(tmp_path / "shot.png")
    pm = PixelMap(s_per_px=s.dt_s)
    anns = []
    for x in _visible(lab):
        x0, y0, x1, y1 = pm.box_to_px(x["box"])
        anns.append({"id": len(anns) + 1, "image_id": 1, "category_id": 1, "bbox": [x0, y0, x1 - x0, y1 - y0]})
    (tmp_path / "c.json").write_text(json.dumps({"images": [{"id": 1, "file_name": "shot.png"}],
                                                 "annotations": anns, "categories": [{"id": 1, "name": "hyperbola"}]}))
    with pytest.raises(GPR3DError, match="picture; give its time axis"):
        read_user_labels(tmp_path / "c.json")
    (g, glab), = read_user_labels(tmp_path / "c.json", pixel_map=f"s_per_px={s.dt_s!r},t0_s=0")
    assert g.shape == s.shape and g.dt_s == pytest.approx(s.dt_s, rel=1e-9, abs=0)
    assert np.corrcoef(g.data.ravel(), d.ravel())[0, 1] > 0.99  # the grey levels are the amplitudes
    have = np.array([x["box"] for x in glab["labels"]])
    want = np.array([x["box"] for x in _visible(lab)])
    np.testing.assert_allclose(have, want, atol=1e-9)
    assert {x["kind"] for x in glab["labels"]} == {"target"}


def test_pixel_map_parsing():
    pm = parse_pixel_map("s_per_px=2e-10, t0_s=1e-9,traces_per_px=2")
    assert pm == PixelMap(trace0=0.0, traces_per_px=2.0, t0_s=1e-9, s_per_px=2e-10)
    for bad, msg in [("t0_s=0", "needs s_per_px"), ("s_per_px=0.1", "not a plausible row interval"),
                     ("s_per_px=1e-10,dx=3", "unknown key"), ("s_per_px", "key=value"),
                     ("s_per_px=abc", "not a number"), ("s_per_px=1e-10,traces_per_px=-1", "must be > 0")]:
        with pytest.raises(GPR3DError, match=msg):
            parse_pixel_map(bad)


@pytest.mark.parametrize("doc, msg", [
    ("{not json", "not valid JSON"),
    ('{"images": []}', "not a COCO detection file"),
    ('{"images": [{"id": 1, "file_name": "gone.h5"}], "annotations": []}', "no such file"),
    ('{"images": [{"id": 1, "file_name": "rec.h5", "width": 50, "height": 50}], '
     '"annotations": [{"id": 1, "image_id": 1, "bbox": [5, 5, 0, 4]}]}', "has no area"),
    ('{"images": [{"id": 1, "file_name": "rec.h5", "width": 50, "height": 50}], '
     '"annotations": [{"id": 1, "image_id": 1, "bbox": [500, 5, 3, 4]}]}', "outside the record"),
    ('{"images": [{"id": 1, "file_name": "rec.h5", "width": 50, "height": 50}], '
     '"annotations": [{"id": 1, "image_id": 1, "bbox": [5, 5, 3]}]}', "must be \\[x, y, w, h\\]"),
])
def test_bad_label_files_name_the_problem(tmp_path, records, doc, msg):
    records[0][0].save(tmp_path / "rec.h5")
    (tmp_path / "l.json").write_text(doc.replace("NaN", "NaN"))
    with pytest.raises(GPR3DError, match=msg):
        read_user_labels(tmp_path / "l.json")
    (tmp_path / "bad.xml").write_text("<annotation><filename>rec.h5</filename><object><bndbox><xmin>a</xmin>"
                                      "</bndbox></object></annotation>")
    with pytest.raises(GPR3DError, match="not a number"):
        read_user_labels(tmp_path / "bad.xml")
    with pytest.raises(GPR3DError, match="COCO .*VOC"):
        read_user_labels(tmp_path / "rec.h5")
    (tmp_path / "map.xml").write_text("<annotation><filename>rec.h5</filename><gpr3d_pixel_map><s_per_px>fast"
                                      "</s_per_px></gpr3d_pixel_map></annotation>")
    with pytest.raises(GPR3DError, match="<s_per_px> = 'fast' is not a number"):
        read_user_labels(tmp_path / "map.xml")
