"""Windows, pixel mapping, merging and apexes, against hand-computed cases and the label rule."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.detection.windows import (Window, WindowConfig, apex_of_box, merge, prepare, width_rate, window_targets,
                                    windows)
from gpr3d.io.coco import BOX_PAD_PERIODS, PixelMap


def test_pixel_map_round_trip_and_hand_case():
    pm = PixelMap(trace0=99.5, traces_per_px=1.0, t0_s=-0.5e-10, s_per_px=1e-10)
    # trace 110 is column 10 (centre at pixel 10.5); 2 ns is row 20 (centre at 20.5)
    assert pm.box_to_px([110, 2e-9, 130, 3e-9]) == pytest.approx([10.5, 20.5, 30.5, 30.5])
    assert pm.px_to_box(pm.box_to_px([110, 2e-9, 130, 3e-9])) == pytest.approx([110, 2e-9, 130, 3e-9], rel=1e-9, abs=0)
    assert pm.px_to_point(*pm.point_to_px(7.25, 1.5e-9)) == pytest.approx((7.25, 1.5e-9), rel=1e-9, abs=0)


def _win(start=100, n=256, real=256):
    return Window(np.zeros((3, 256, n), np.float32), PixelMap(trace0=start - 0.5, t0_s=-0.5e-10, s_per_px=1e-10),
                  start, real)


def test_window_targets_keep_clip_and_drop():
    lab = lambda box, apex: {"box": box, "apex_trace": apex, "apex_time_s": box[1] + 1e-10, "visible": True}
    w = _win()
    inside = lab([120, 2e-9, 160, 4e-9], 140)
    cut_ok = lab([320, 2e-9, 370, 4e-9], 340)      # pixels 220.5..270.5: 35.5 of 50 inside, 71 % >= 60 %
    cut_bad = lab([340, 2e-9, 420, 4e-9], 352)     # 15.5 of 80 inside: dropped
    apex_out = lab([60, 2e-9, 120, 4e-9], 90)      # apex left of the window
    hidden = dict(inside, visible=False)
    got = window_targets([inside, cut_ok, cut_bad, apex_out, hidden], w)
    assert got == pytest.approx(np.array([[20.5, 20.5, 60.5, 40.5], [220.5, 20.5, 256, 40.5]]))


def test_merge_prefers_the_whole_box_and_maps_back():
    dt = 1e-10
    left, right = _win(0), _win(128)
    left = Window(left.image, left.pixmap, 0, 256)
    # the same hyperbola: cut by the left window's right edge, whole in the right window
    cut = np.array([[200.0, 20.0, 256.0, 40.0]])
    whole = np.array([[72.5, 20.5, 152.5, 40.5]])  # traces 200..280, 2..4 ns
    boxes, scores = merge([(left, cut, np.array([0.9])), (right, whole, np.array([0.8]))], n_traces=600, dt_s=dt)
    assert len(boxes) == 1
    assert scores[0] == pytest.approx(0.8)
    assert boxes[0] == pytest.approx([200, 2e-9, 280, 4e-9], rel=1e-9, abs=0)


def test_merge_keeps_neighbours_apart():
    w = _win(0)
    b = np.array([[10.0, 10, 60, 40], [45.0, 10, 95, 40]])  # IoU 15/85: two targets
    boxes, _ = merge([(w, b, np.array([0.9, 0.8]))], n_traces=256, dt_s=1e-10)
    assert len(boxes) == 2


def _point_record(x_t=0.6, depth=0.2, eps=6.0, f=800e6, n=121, step=0.01, dt=0.02e-9, ns=768, start=0.0):
    """A clean B-scan of a point target with a Ricker pulse (peak at the true two-way time + delay)."""
    v = 299792458.0 / math.sqrt(eps)
    x = start + step * np.arange(n)
    twt = 2 * np.hypot(x - x_t, depth) / v
    delay = math.sqrt(2) / f
    t = np.arange(ns) * dt
    a = (np.pi * f * (t[None, :] - delay - twt[:, None])) ** 2
    data = ((1 - 2 * a) * np.exp(-a)).astype(np.float32)
    pos = np.stack([x, 0 * x, 0 * x], axis=1)
    s = Survey(data=data, dt_s=dt, positions_xyz=pos, frequency_hz=f, eps_r=eps)
    apex_trace = (x_t - start) / step
    return s, apex_trace, delay + 2 * depth / v, twt + delay


def test_apex_from_box_rule_and_from_data_at_the_record_edge():
    s, apex_tr, apex_t, arr = _point_record()
    cfg = WindowConfig()
    proc = prepare(s, cfg)
    spr = (s.n_samples - 1) * s.dt_s / (cfg.rows - 1)
    f = s.frequency_hz
    box = [apex_tr - 20, apex_t - BOX_PAD_PERIODS / f, apex_tr + 20, arr.max() + BOX_PAD_PERIODS / f]
    tr, t = apex_of_box(proc, box, spr, frequency_hz=f)
    assert tr == pytest.approx(apex_tr, rel=1e-9, abs=0) and t == pytest.approx(apex_t, rel=1e-9, abs=0)
    # without a frequency, the apex time comes from the envelope on the apex trace (of unequalised data)
    plain = prepare(s, WindowConfig(equalise=False))
    tr, t = apex_of_box(plain, box, spr)
    assert abs(t - apex_t) < 0.25 / f
    # a box cut by the record's first trace: the apex trace comes from the data
    s2, apex2, apex_t2, _ = _point_record(x_t=0.1)
    proc2 = prepare(s2, cfg)
    tr2, _ = apex_of_box(proc2, [0, apex_t2 - 1e-9, apex2 + 25, apex_t2 + 4e-9], spr, frequency_hz=f,
                         n_traces=s2.n_traces)
    assert abs(tr2 - apex2) <= 2


def test_cut_boxes_take_their_width_from_the_record_s_whole_boxes():
    """Under the label rule a box's width over its height (less the pads) is one number per record, whatever the
    target's depth and radius; a box cut by the record's edge then gives its apex from its height."""
    from gpr3d.simulation.labels import label_scene
    from gpr3d.simulation.scene import Antenna, Medium, Scene, Target

    scene = Scene(medium=Medium("concrete", 7.0, 0.005), antenna=Antenna(1.5e9, 0.02), width_m=1.0, depth_m=0.4,
                  n_traces=150, trace_step_m=0.005, x_start_m=0.1, time_window_s=8e-9,
                  targets=[Target("rebar", x_m=0.12, depth_m=0.05, radius_m=0.008),      # cut by the first trace
                           Target("rebar", x_m=0.30, depth_m=0.04, radius_m=0.006),
                           Target("steel_pipe", x_m=0.45, depth_m=0.10, radius_m=0.03),
                           Target("void", x_m=0.60, depth_m=0.07, radius_m=0.02),
                           Target("pvc_pipe", x_m=0.82, depth_m=0.09, radius_m=0.02)])  # cut by the last trace
    n_samples, dt = 801, 1e-11
    labels = label_scene(scene, n_samples, dt)
    boxes = [lab["box"] for lab in labels]
    cut = [lab for lab in labels if lab["box"][0] == 0 or lab["box"][2] == scene.n_traces - 1]
    assert len(cut) == 2 and all(lab["visible"] for lab in labels)
    t_end = (n_samples - 1) * dt
    f = scene.antenna.frequency_hz
    rate = width_rate(boxes, scene.n_traces, t_end, f)
    v = 299792458.0 / math.sqrt(7.0)  # the rule's rate: v tan45 / (dx (1/cos45 - 1)), up to whole traces
    assert rate == pytest.approx(v / (0.005 * (math.sqrt(2) - 1)), rel=0.05)
    blank = np.zeros((scene.n_traces, 256))
    spr = t_end / 255
    for lab in cut:
        tr, t = apex_of_box(blank, lab["box"], spr, frequency_hz=f, n_traces=scene.n_traces, width_per_s=rate)
        assert abs(tr - lab["apex_trace"]) <= 1.5 and t == pytest.approx(lab["apex_time_s"], rel=1e-9, abs=0)
    assert width_rate([b for b in boxes if b[0] == 0], scene.n_traces, t_end, f) is None  # no whole box: no rate
    assert width_rate(boxes, scene.n_traces, t_end, None) is None


def test_prepare_keeps_time_from_the_first_sample():
    s, apex_tr, apex_t, _ = _point_record()
    cfg = WindowConfig(equalise=False)
    proc = prepare(s, cfg)
    spr = (s.n_samples - 1) * s.dt_s / (cfg.rows - 1)
    row = int(np.argmax(np.abs(proc[int(apex_tr)])))
    assert abs(row * spr - apex_t) < 2 * spr


def test_windows_cover_the_record_and_reject_bad_input():
    s, *_ = _point_record(n=600)
    ws = windows(s, WindowConfig(traces=256, overlap=0.5))
    assert [w.trace_start for w in ws] == [0, 128, 256, 344]
    assert all(w.image.shape == (3, 256, 256) for w in ws)
    bad = SimpleNamespace(data=np.where(np.arange(s.n_samples) == 5, np.nan, s.data), dt_s=s.dt_s,
                          frequency_hz=s.frequency_hz, n_samples=s.n_samples)
    with pytest.raises(InvalidDataError, match="NaN"):
        prepare(bad)
    with pytest.raises(InvalidDataError, match="overlap"):
        WindowConfig(overlap=0.95)
