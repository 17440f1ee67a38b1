"""B-scan boxes <-> image pixels and the COCO JSON of simulated records, by hand."""

import pytest

from gpr3d.io.coco import BOX_HALF_ANGLE_DEG, BOX_PAD_PERIODS, CATEGORIES, PixelMap, coco_dataset


def test_the_pixel_map_both_ways_by_hand():
    pm = PixelMap(trace0=10.0, traces_per_px=2.0, t0_s=1e-9, s_per_px=0.5e-9)
    # trace 14 at column 2, 3 ns at row 4; trace 30 at column 10, 6 ns at row 10
    assert pm.box_to_px([14, 3e-9, 30, 6e-9]) == pytest.approx([2.0, 4.0, 10.0, 10.0])
    assert pm.px_to_box([2.0, 4.0, 10.0, 10.0]) == pytest.approx([14.0, 3e-9, 30.0, 6e-9], rel=1e-9, abs=0)
    assert pm.point_to_px(12.0, 2e-9) == pytest.approx((1.0, 2.0))
    assert pm.px_to_point(1.0, 2.0) == pytest.approx((12.0, 2e-9), rel=1e-9, abs=0)
    ident = PixelMap()
    assert ident.box_to_px([1, 2, 3, 4]) == [1.0, 2.0, 3.0, 4.0] and ident.px_to_box([1, 2, 3, 4]) == [1, 2, 3, 4]
    assert ident.point_to_px(5, 6) == (5, 6) and ident.px_to_point(5, 6) == (5, 6)


def test_the_label_rule_constants():
    assert (BOX_HALF_ANGLE_DEG, BOX_PAD_PERIODS) == (45.0, 0.7)
    assert CATEGORIES == ["rebar", "steel_pipe", "pvc_pipe", "void", "tank"]


def test_coco_dataset_by_hand():
    """A record of 101 samples of 0.1 ns (10 ns) drawn 51 rows tall: 0.2 ns per row. A box over traces 4..12 and
    2..5 ns is x 4, y 10, w 8, h 15; an invisible label is left out; ids count over the whole set."""
    lab = {"visible": True, "box": [4, 2e-9, 12, 5e-9], "category": 3, "apex_trace": 8, "apex_time_s": 2.5e-9,
           "depth_m": 0.2}
    samples = [{"id": 7, "file_name": "a.png", "n_traces": 30, "dt_s": 0.1e-9, "n_samples": 101, "eps_r": 6.0,
                "labels": [lab, dict(lab, visible=False), dict(lab, box=[0, 0.0, 1, 1e-9], category=1)]},
               {"id": 8, "file_name": "b.png", "n_traces": 20, "dt_s": 0.2e-9, "n_samples": 51, "eps_r": 9.0,
                "labels": [dict(lab, box=[2, 1e-9, 6, 3e-9])]}]
    c = coco_dataset(samples, 51)
    assert c["images"][0] == {"id": 7, "file_name": "a.png", "width": 30, "height": 51, "eps_r": 6.0,
                              "row_s": pytest.approx(0.2e-9, rel=1e-9, abs=0)}
    assert c["images"][1]["row_s"] == pytest.approx(0.2e-9, rel=1e-9, abs=0)
    a = c["annotations"]
    assert [x["id"] for x in a] == [1, 2, 3] and [x["image_id"] for x in a] == [7, 7, 8]
    assert a[0]["bbox"] == pytest.approx([4.0, 10.0, 8.0, 15.0]) and a[0]["area"] == pytest.approx(120.0)
    assert (a[0]["category_id"], a[0]["iscrowd"], a[0]["apex_trace"], a[0]["apex_time_s"], a[0]["depth_m"]) == \
        (3, 0, 8, 2.5e-9, 0.2)
    assert a[1]["bbox"] == pytest.approx([0.0, 0.0, 1.0, 5.0]) and a[1]["category_id"] == 1
    assert a[2]["bbox"] == pytest.approx([2.0, 5.0, 4.0, 10.0])
    assert c["categories"][0] == {"id": 1, "name": "rebar", "supercategory": "target"}
    assert [x["id"] for x in c["categories"]] == [1, 2, 3, 4, 5]
    assert c["info"] == {"description": "gpr3d simulated B-scans"}
