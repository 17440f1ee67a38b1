import math

import numpy as np
import pytest

from gpr3d.simulation.labels import coco_dataset, hyperbola_times, label_scene
from gpr3d.simulation.scene import Antenna, Medium, Scene, Target


def scene(offset=0.0):
    return Scene(medium=Medium(eps_r=9.0), antenna=Antenna(frequency_hz=1e9, offset_m=offset),
                 targets=[Target("rebar", x_m=0.5, depth_m=0.2, radius_m=0.01)],
                 width_m=1.0, depth_m=0.5, n_traces=51, trace_step_m=0.02, x_start_m=0.0)


def test_zero_offset_times_are_the_distance_to_the_circle():
    s = scene()
    t = s.targets[0]
    x = s.trace_midpoints_x()
    expect = 2 * (np.hypot(x - t.x_m, t.depth_m + t.radius_m) - t.radius_m) / s.medium.velocity_m_s
    np.testing.assert_allclose(hyperbola_times(s, t), expect, rtol=1e-7)


def test_offset_apex_time():
    s = scene(offset=0.1)
    t = s.targets[0]
    # above the target the shortest path touches the top: two legs of hypot(0.05, depth)
    expect = 2 * math.hypot(0.05, t.depth_m) / s.medium.velocity_m_s
    assert hyperbola_times(s, t)[25] == pytest.approx(expect, rel=1e-6)


def test_labels_and_box_rule():
    s = scene()
    n, dt = 400, 0.02e-9
    lab = label_scene(s, n, dt)[0]
    f = s.antenna.frequency_hz
    assert lab["apex_trace"] == pytest.approx(25.0)
    assert lab["apex_time_s"] == pytest.approx(math.sqrt(2) / f + 2 * 0.2 / s.medium.velocity_m_s)
    i0, t0, i1, t1 = lab["box"]
    reach = (0.21) * math.tan(math.radians(45))  # depth to centre * tan(45)
    assert (i0, i1) == (int(np.ceil((0.5 - reach) / 0.02 - 1e-9)), int((0.5 + reach) / 0.02 + 1e-9))
    assert t0 == pytest.approx(lab["apex_time_s"] - 0.7 / f)
    assert t0 < lab["apex_time_s"] < t1 <= (n - 1) * dt
    assert lab["visible"]


def test_coco_json_loads_in_pycocotools(tmp_path):
    coco_mod = pytest.importorskip("pycocotools.coco")
    import json

    s = scene()
    labs = label_scene(s, 400, 0.02e-9)
    d = coco_dataset([{"id": 1, "file_name": "a.png", "n_traces": 51, "n_samples": 400, "dt_s": 0.02e-9,
                       "eps_r": 9.0, "labels": labs}], image_height=200)
    (tmp_path / "c.json").write_text(json.dumps(d))
    coco = coco_mod.COCO(str(tmp_path / "c.json"))
    ann = coco.loadAnns(coco.getAnnIds(imgIds=[1]))[0]
    x, y, w, h = ann["bbox"]
    row_s = 399 * 0.02e-9 / 199
    assert y == pytest.approx(labs[0]["box"][1] / row_s)
    assert x == labs[0]["box"][0] and w == labs[0]["box"][2] - labs[0]["box"][0]
    assert ann["depth_m"] == 0.2 and coco.imgs[1]["eps_r"] == 9.0
    assert coco.loadCats(ann["category_id"])[0]["name"] == "rebar"
