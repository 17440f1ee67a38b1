"""Survey-scale scenes: stated ranges, labels at the traces' real positions, apexes on the echoes."""

import math

import numpy as np
import pytest

from gpr3d.simulation.labels import label_scene, label_traces
from gpr3d.simulation.surveys import SURVEY_RANGES, sample_survey_scene, synthesize_survey


def test_scenes_follow_the_stated_ranges():
    for i in range(40):
        s = sample_survey_scene(3, i)
        r = SURVEY_RANGES[s.medium.kind]
        assert SURVEY_RANGES["n_traces"][0] <= s.n_traces <= SURVEY_RANGES["n_traces"][1]
        assert r["eps_r"][0] <= s.medium.eps_r <= r["eps_r"][1]
        assert s.targets
        if s.medium.kind == "concrete":
            bars = [t for t in s.targets if t.kind == "rebar"]
            top = min(t.depth_m for t in bars)
            assert r["cover_m"][0] - 1e-4 <= top <= r["cover_m"][1] + 1e-4
            assert all(r["rebar_radius_m"][0] - 1e-4 <= t.radius_m <= r["rebar_radius_m"][1] + 1e-4 for t in bars)
            assert 1.0e9 <= s.antenna.frequency_hz <= 2.6e9
        else:
            assert 1e8 <= s.antenna.frequency_hz <= 9e8
            assert all(t.depth_m <= 2.0 + 1e-6 for t in s.targets)


def test_label_traces_equals_label_scene_on_even_steps_and_follows_stops():
    s = sample_survey_scene(3, 1, host="soil")
    a = label_scene(s, 512, s.time_window / 512)
    b = label_traces(s, s.trace_midpoints_x(), 512, s.time_window / 512)
    assert a == b
    # the cart stops for 20 traces half-way: apexes after the stop move 20 traces on
    x = s.trace_midpoints_x()
    k = s.n_traces // 2
    stopped = np.concatenate([x[:k], np.full(20, x[k - 1]), x[k:]])
    c = label_traces(s, stopped, 512, s.time_window / 512)
    for la, lc, t in zip(a, c, s.targets):
        shift = 20 if t.x_m > x[k - 1] else 0
        assert lc["apex_trace"] == pytest.approx(la["apex_trace"] + shift, abs=1e-6)
        assert lc["apex_time_s"] == pytest.approx(la["apex_time_s"], rel=1e-9, abs=0)


def test_labelled_apex_lies_on_the_echo():
    s, lab = synthesize_survey(sample_survey_scene(3, 2, host="soil"), seed=1, augment=False)
    f = s.frequency_hz
    from scipy.signal import hilbert

    env = np.abs(hilbert(s.remove_background().data, axis=1))
    checked = 0
    for l in lab["labels"]:
        if not l["visible"] or l["kind"] in ("void", "pvc_pipe"):
            continue
        i = int(round(l["apex_trace"]))
        j0 = int((l["apex_time_s"] - 0.6 / f) / s.dt_s)
        j1 = int((l["apex_time_s"] + 0.6 / f) / s.dt_s)
        j = j0 + int(np.argmax(env[i, j0:j1]))
        assert abs(j * s.dt_s - l["apex_time_s"]) < 0.25 / f
        checked += 1
    assert checked


def test_augmented_surveys_are_seeded():
    a, la = synthesize_survey(sample_survey_scene(3, 4), seed=9)
    b, lb = synthesize_survey(sample_survey_scene(3, 4), seed=9)
    c, _ = synthesize_survey(sample_survey_scene(3, 4), seed=10)
    assert np.array_equal(a.data, b.data) and la == lb
    assert not np.array_equal(a.data[: min(a.n_traces, c.n_traces)], c.data[: min(a.n_traces, c.n_traces)]) \
        or a.shape != c.shape
    assert math.isfinite(float(np.abs(a.data).max()))
