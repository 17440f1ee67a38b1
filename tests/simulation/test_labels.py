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
    assert hyperbola_times(s, t)[25] == pytest.approx(expect, rel=1e-6, abs=0)


def test_labels_and_box_rule():
    s = scene()
    n, dt = 400, 0.02e-9
    lab = label_scene(s, n, dt)[0]
    f = s.antenna.frequency_hz
    assert lab["apex_trace"] == pytest.approx(25.0)
    assert lab["apex_time_s"] == pytest.approx(math.sqrt(2) / f + 2 * 0.2 / s.medium.velocity_m_s, rel=1e-9, abs=0)
    i0, t0, i1, t1 = lab["box"]
    reach = (0.21) * math.tan(math.radians(45))  # depth to centre * tan(45)
    assert (i0, i1) == (int(np.ceil((0.5 - reach) / 0.02 - 1e-9)), int((0.5 + reach) / 0.02 + 1e-9))
    assert t0 == pytest.approx(lab["apex_time_s"] - 0.7 / f, rel=1e-9, abs=0)
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


# ---------------------------------------------------------------- every label field, and traces that stop or miss

from gpr3d.simulation.labels import label_traces  # noqa: E402


def test_every_field_of_a_label_by_hand():
    s = scene()
    s.targets.append(Target("steel_pipe", x_m=0.3, depth_m=0.1, radius_m=0.05))
    n, dt = 400, 0.02e-9
    labs = label_scene(s, n, dt)
    f, v = 1e9, s.medium.velocity_m_s
    b = labs[1]
    assert (b["kind"], b["category"], b["depth_m"], b["x_m"], b["radius_m"]) == ("steel_pipe", 2, 0.1, 0.3, 0.05)
    assert labs[0]["category"] == 1  # rebar
    assert b["apex_twt_s"] == pytest.approx(2 * 0.1 / v, rel=1e-6, abs=0)
    assert b["apex_time_s"] == pytest.approx(math.sqrt(2) / f + 2 * 0.1 / v, rel=1e-6, abs=0)
    assert b["apex_trace"] == pytest.approx(15.0)
    reach = 0.15  # depth to the centre times tan 45
    i0, t0, i1, t1 = b["box"]
    assert (i0, i1) == (8, 22)  # x within 0.15 m of 0.3: 0.16 .. 0.44
    far = 2 * (math.hypot(0.14, 0.15) - 0.05) / v  # the latest arrival: the box's outermost traces
    assert t1 == pytest.approx(math.sqrt(2) / f + far + 0.7 / f, rel=1e-5, abs=0)
    assert t0 == pytest.approx(b["apex_time_s"] - 0.7 / f, rel=1e-9, abs=0)
    assert b["visible"] and reach > 0


def test_a_short_record_clips_the_box_and_hides_the_apex():
    s = scene()
    n, dt = 100, 0.02e-9  # 1.98 ns: the apex (1.41 + 2.6 ns) lies past the end
    lab = label_scene(s, n, dt)[0]
    assert lab["box"][3] == pytest.approx((n - 1) * dt, rel=1e-9, abs=0) and not lab["visible"]
    s.targets[0].depth_m = 0.01  # shallow, and no source delay: the box would start before the record
    lab = label_traces(s, s.trace_midpoints_x(), 400, 0.02e-9, source_delay_s=0.0)[0]
    # clipped at 0
    assert lab["apex_time_s"] == pytest.approx(lab["apex_twt_s"], rel=1e-9, abs=0) and lab["box"][1] == 0.0


def test_stops_gaps_and_a_target_beside_the_line():
    s = scene()
    x = np.array([0.0, 0.1, 0.2, 0.2, 0.2, 0.45, 0.55, 0.8])  # a stop at 0.2 m, a gap, uneven steps
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(5.5)  # half-way between the traces at 0.45 and 0.55
    assert (lab["box"][0], lab["box"][2]) == (5, 6)  # within 0.5 +- 0.21 m: the traces at 0.45 and 0.55
    s.targets[0].x_m = 1.5  # past the end of the line: extrapolated with the mean step (0.8 / 7)
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(1.5 / (0.8 / 7)) and not lab["visible"]
    assert lab["box"][0] == lab["box"][2] == 7  # no trace within reach: the nearest
    s.targets[0].x_m = -0.3  # before the start
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(-0.3 / (0.8 / 7)) and not lab["visible"]
    one = label_traces(scene(), np.array([0.5]), 400, 0.02e-9)[0]  # one trace: it is the apex
    assert one["apex_trace"] == 0.0 and one["visible"]


def test_the_circle_path_with_offset_off_the_apex():
    """A trace 0.3 m from a 5 cm pipe's axis, tx and rx 0.2 m apart: the shortest path over the upper half circle,
    against a dense search of the circle."""
    s = Scene(medium=Medium(eps_r=4.0), antenna=Antenna(frequency_hz=1e9, offset_m=0.2),
              targets=[Target("steel_pipe", x_m=0.0, depth_m=0.3, radius_m=0.05)],
              width_m=1.0, depth_m=0.6, n_traces=3, trace_step_m=0.3, x_start_m=-0.3)
    t = s.targets[0]
    a = np.linspace(0, np.pi, 2_000_001)
    px, pz = 0.05 * np.cos(a), -0.35 + 0.05 * np.sin(a)
    for x in (-0.3, 0.0, 0.3):
        want = np.min(np.hypot(px - (x - 0.1), pz) + np.hypot(px - (x + 0.1), pz)) / s.medium.velocity_m_s
        assert hyperbola_times(s, t, [x])[0] == pytest.approx(want, rel=1e-8, abs=0), x


def test_labels_as_json_text():
    from gpr3d.simulation.labels import to_json

    assert to_json({"a": [1, 2], "b": "x"}) == '{\n "a": [\n  1,\n  2\n ],\n "b": "x"\n}'


def test_the_circle_path_refinement_on_a_coarse_set_of_angles():
    """13 angles over the half circle, refined by a parabola through the best three: within 5e-5 of a dense search
    (the plain minimum over 13 angles is ~1e-3 off); the default 721 angles within 1e-9."""
    from gpr3d.simulation.labels import _circle_path

    tx = np.array([-0.4, -0.1, 0.2])
    rx = tx + 0.2
    cx, cz, r = 0.05, -0.35, 0.05
    a = np.linspace(0, np.pi, 2_000_001)
    px, pz = cx + r * np.cos(a), cz + r * np.sin(a)
    want = np.array([np.min(np.hypot(px - t, pz) + np.hypot(px - u, pz)) for t, u in zip(tx, rx)])
    np.testing.assert_allclose(_circle_path(tx, rx, cx, cz, r, n_angles=13), want, rtol=5e-5)
    np.testing.assert_allclose(_circle_path(tx, rx, cx, cz, r), want, rtol=1e-9)


def test_labels_of_a_line_that_starts_away_from_zero():
    """The same stops and gaps 1 m further along: apex traces and the extrapolation step count from the first
    trace, not from x = 0."""
    s = scene()
    s.targets[0].x_m = 1.5
    x = 1.0 + np.array([0.0, 0.1, 0.2, 0.2, 0.2, 0.45, 0.55, 0.8])
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(5.5) and (lab["box"][0], lab["box"][2]) == (5, 6)
    s.targets[0].x_m = 2.5
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(1.5 / (0.8 / 7))
    s.targets[0].x_m = 1.8  # exactly at the last trace: inside, its index
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(7.0) and lab["visible"]


def _via(tx, rx, cx, cz, r, ang):
    px, pz = cx + r * math.cos(ang), cz + r * math.sin(ang)
    return math.hypot(px - tx, pz) + math.hypot(px - rx, pz)


def test_the_circle_path_keeps_the_end_angles_unrefined_and_refines_the_next_ones():
    """Five angles (0, 45, 90, 135, 180 deg): a trace far to the right is nearest over angle 0, far to the left over
    180 (no neighbour on one side: the plain value); nearer ones over 45 and 135, refined by the parabola."""
    from gpr3d.simulation.labels import _circle_path

    cx, cz, r = 0.0, -0.3, 0.1
    tx = np.array([5.0, -5.0, 0.25, -0.25])
    got = _circle_path(tx, tx, cx, cz, r, n_angles=5)
    ang = np.linspace(0, np.pi, 5)
    assert got[0] == _via(5.0, 5.0, cx, cz, r, 0.0) and got[1] == _via(-5.0, -5.0, cx, cz, r, math.pi)
    for j, k in ((2, 1), (3, 3)):
        y0, y1, y2 = (_via(tx[j], tx[j], cx, cz, r, ang[k + d]) for d in (-1, 0, 1))
        assert y1 <= min(y0, y2)  # the best of the five
        want = y1 - (y0 - y2) ** 2 / (8 * (y0 - 2 * y1 + y2))
        assert got[j] == pytest.approx(want, rel=1e-14, abs=0) and got[j] < y1


def test_a_point_target_has_the_same_path_at_every_angle_and_no_refinement():
    from gpr3d.simulation.labels import _circle_path

    tx = np.array([-0.2, 0.0, 0.3])
    got = _circle_path(tx, tx + 0.1, 0.05, -0.4, 0.0)
    want = np.hypot(0.05 - tx, 0.4) + np.hypot(0.05 - (tx + 0.1), 0.4)
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
    assert np.all(np.isfinite(got))


def test_a_trace_exactly_at_the_box_reach_is_inside():
    from gpr3d.io.coco import BOX_HALF_ANGLE_DEG

    s = scene()
    s.targets[0].x_m = 0.0
    reach = (0.2 + 0.01) * math.tan(math.radians(BOX_HALF_ANGLE_DEG))
    x = np.array([-2 * reach, -reach, 0.0, reach, np.nextafter(reach, 1.0) + 1e-9])
    lab = label_traces(s, x, 400, 0.02e-9)[0]
    assert (lab["box"][0], lab["box"][2]) == (1, 3)


def test_apex_traces_on_two_positions_a_stop_at_the_end_and_lines_of_one_place():
    s = scene()
    s.targets[0].x_m = 0.05
    assert label_traces(s, np.array([0.0, 0.1]), 400, 0.02e-9)[0]["apex_trace"] == pytest.approx(0.5)
    s.targets[0].x_m = 0.3  # past a two-trace line: the step is its one interval
    assert label_traces(s, np.array([0.0, 0.1]), 400, 0.02e-9)[0]["apex_trace"] == pytest.approx(3.0)
    s.targets[0].x_m = 0.2  # exactly at the last place, where the cart stood for three traces: its first trace
    lab = label_traces(s, np.array([0.0, 0.1, 0.2, 0.2, 0.2]), 400, 0.02e-9)[0]
    assert lab["apex_trace"] == 2.0
    s.targets[0].x_m = 0.7  # a cart that never moved: the step falls back to 1 m
    lab = label_traces(s, np.array([0.5, 0.5, 0.5]), 400, 0.02e-9)[0]
    assert lab["apex_trace"] == pytest.approx(0.2, rel=1e-12, abs=0) and lab["visible"]


def test_visible_up_to_the_record_s_ends_inclusive():
    s = scene()
    x = np.array([0.0, 0.1, 0.2])
    s.targets[0].x_m = 0.25  # half a step past the last trace (index 2.5 of 3): not visible
    assert not label_traces(s, x, 400, 0.02e-9)[0]["visible"]
    s.targets[0].x_m = 0.1
    a = label_traces(s, x, 400, 0.02e-9, source_delay_s=0.0)[0]["apex_twt_s"]
    # the apex exactly at the first sample (a negative source delay): visible
    assert label_traces(s, x, 400, 0.02e-9, source_delay_s=-a)[0]["visible"]
    assert not label_traces(s, x, 400, 0.02e-9, source_delay_s=np.nextafter(-a, -1.0))[0]["visible"]
    # and exactly at the last sample
    t_end = 399 * 0.02e-9
    d = t_end - a
    while d + a > t_end:
        d = np.nextafter(d, -1.0)
    while d + a < t_end:
        d = np.nextafter(d, 1.0)
    assert d + a == t_end
    assert label_traces(s, x, 400, 0.02e-9, source_delay_s=d)[0]["visible"]
    assert not label_traces(s, x, 400, 0.02e-9, source_delay_s=np.nextafter(d, 1.0) + 1e-15)[0]["visible"]


def test_a_time_pad_of_its_own_moves_only_the_box_s_times():
    """``pad_periods``: the box reaches that many periods before the apex and after the latest arrival (by hand, as
    above: a steel pipe at 0.1 m, its box's outermost traces 0.14 m off its axis), the traces and the rest kept."""
    s = scene()
    s.targets.append(Target("steel_pipe", x_m=0.3, depth_m=0.1, radius_m=0.05))
    n, dt, f, v = 400, 0.02e-9, 1e9, s.medium.velocity_m_s
    x = s.trace_midpoints_x()
    rule = label_traces(s, x, n, dt)
    assert rule == label_traces(s, x, n, dt, pad_periods=0.7)  # the rule's own pad
    tight = label_traces(s, x, n, dt, pad_periods=0.4)
    b = tight[1]
    i0, t0, i1, t1 = b["box"]
    assert (i0, i1) == (8, 22)
    far = 2 * (math.hypot(0.14, 0.15) - 0.05) / v
    assert t1 == pytest.approx(math.sqrt(2) / f + far + 0.4 / f, rel=1e-5, abs=0)
    assert t0 == pytest.approx(math.sqrt(2) / f + 2 * 0.1 / v - 0.4 / f, rel=1e-9, abs=0)
    for a, r in zip(tight, rule):
        assert {k: v for k, v in a.items() if k != "box"} == {k: v for k, v in r.items() if k != "box"}
        assert a["box"][1] - r["box"][1] == pytest.approx(0.3 / f) or r["box"][1] == 0.0
    assert label_traces(s, x, n, dt, pad_periods=0.0)[1]["box"][1] == pytest.approx(b["apex_time_s"], rel=1e-12)
    assert label_traces(s, x, n, dt, pad_periods=2.0)[1]["box"][1] == pytest.approx(b["apex_time_s"] - 2.0 / f)
    for bad in (-0.1, 2.01, float("nan")):
        with pytest.raises(ValueError, match="pad_periods must lie in 0..2"):
            label_traces(s, x, n, dt, pad_periods=bad)
