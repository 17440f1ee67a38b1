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


def test_wall_scenes_follow_their_ranges_and_are_not_the_training_draws():
    from gpr3d.simulation.surveys import SURVEY_PROFILES, WALL_RANGES

    r, prof = WALL_RANGES, SURVEY_PROFILES["wall"]
    for i in range(30):
        s = sample_survey_scene(3, i, profile="wall")
        assert s.medium.kind == "concrete"
        assert prof["n_traces"][0] <= s.n_traces <= prof["n_traces"][1]
        assert r["frequency_hz"][0] - 1e6 <= s.antenna.frequency_hz <= r["frequency_hz"][1] + 1e6
        assert r["step_m"][0] - 1e-5 <= s.trace_step_m <= r["step_m"][1] + 1e-5
        assert r["eps_r"][0] <= s.medium.eps_r <= r["eps_r"][1]
        assert s.time_window >= r["window_s"][0] and s.time_window >= 2 * s.depth_m / s.medium.velocity_m_s
        bars = sorted((t for t in s.targets if t.kind == "rebar"), key=lambda t: t.x_m)
        top = min(t.depth_m for t in bars)
        assert r["cover_m"][0] - 1e-4 <= top <= r["cover_m"][1] + 1e-4
        first = [t.x_m for t in bars if abs(t.depth_m - top) < 1e-6]
        assert np.all(np.diff(first) >= 0.95 * r["rebar_spacing_m"][0] - 1e-4)
        assert s.to_dict() != sample_survey_scene(3, i).to_dict() and s.name == f"survey_wall_3_{i:06d}"
    with pytest.raises(ValueError, match="wall scans are of concrete, got host 'soil'"):
        sample_survey_scene(3, 0, host="soil", profile="wall")


def test_display_8bit_keeps_the_order_of_amplitudes_in_256_grey_levels_and_clips_the_strongest():
    from gpr3d.simulation.surveys import display_8bit

    rng = np.random.default_rng(0)
    data = rng.normal(size=(200, 64))
    data[:, 5] = 40.0  # a direct wave far above the rest
    for seed in range(6):
        out = display_8bit(data, np.random.default_rng(seed))
        assert np.array_equal(out, np.round(out)) and out.min() >= 1 and out.max() <= 255
        assert np.all(out[:, 5] == 255)  # saturated: at most 0.6 of the peak is shown
        for j in (10, 40):  # along one time sample (one gain), grey follows amplitude
            order = np.argsort(data[:, j], kind="stable")
            assert np.all(np.diff(out[order, j]) >= 0)
    zero = display_8bit(np.zeros((4, 8)), np.random.default_rng(1))
    assert np.all(zero == 128)


def test_wall_noise_is_smooth_across_traces_and_lies_in_the_radar_band():
    from gpr3d.simulation.surveys import _correlated_noise

    f, dt = 1.6e9, 2.5e-11
    n = _correlated_noise((400, 512), dt, f, np.random.default_rng(2))
    assert abs(np.std(n) - 1) < 1e-9
    assert np.abs(n.mean(axis=1)).max() < 1e-9  # no offset in any trace
    adj = np.mean([np.corrcoef(n[i], n[i + 1])[0, 1] for i in range(0, 398, 7)])
    assert adj > 0.4
    spec = np.mean(np.abs(np.fft.rfft(n, axis=1)) ** 2, axis=0)
    freqs = np.fft.rfftfreq(512, dt)
    peak = freqs[np.argmax(spec)]
    assert 0.7 * f < peak < 1.3 * f
    assert spec[freqs > 4 * f].sum() < 1e-3 * spec.sum()


def test_wall_samples_are_labelled_records_mostly_kept_as_8bit_pictures():
    from gpr3d.simulation.surveys import SurveySource, survey_sample

    kept8 = 0
    for i in range(8):
        s, lab = survey_sample(5, i, profile="wall")
        assert s.n_samples == lab["n_samples"] and s.n_traces == lab["n_traces"]
        assert (s.n_samples - 1) * s.dt_s >= 5.9e-9
        assert any(x["kind"] == "rebar" for x in lab["labels"])
        for x in lab["labels"]:
            assert -1 <= x["apex_trace"] <= s.n_traces and 0 < x["apex_time_s"] < s.n_samples * s.dt_s
        kept8 += bool(np.array_equal(s.data, np.round(s.data)) and s.data.min() >= 1 and s.data.max() <= 255)
    assert 3 <= kept8 <= 8  # 80 % of them on average
    src = SurveySource(5, profile="wall")
    assert np.array_equal(src(2)[0].data, survey_sample(5, 2, profile="wall")[0].data)
    with pytest.raises(ValueError, match="'train' or 'wall'"):
        SurveySource(5, profile="walls")


def test_echo_ringing_follows_each_echo_by_its_decaying_copies():
    from gpr3d.simulation.surveys import echo_ringing

    f, dt, n = 1.6e9, 1e-11, 600
    data = np.zeros((2, n))
    data[0, 100] = 1.0  # an impulse: the output is the kernel itself
    data[1, 300] = -2.0
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    out = echo_ringing(data, dt, f, rng_a)
    fr, tau, a = f * rng_b.uniform(0.7, 1.3), rng_b.uniform(1.0, 4.0) / f, rng_b.uniform(0.3, 0.8)
    # the kernel by hand: the impulse, then after one period of f a sinusoid at fr decaying over tau
    t = np.arange(n) * dt - 1 / f
    tail = np.where(t >= 0, np.sin(2 * np.pi * fr * t) * np.exp(-np.clip(t, 0, None) / tau), 0.0)
    gain = abs(np.sum(tail * np.exp(-2j * np.pi * fr * np.arange(n) * dt)))
    kernel = a * tail / gain
    kernel[0] += 1
    np.testing.assert_allclose(out[0, 100:], kernel[: n - 100], atol=1e-12)
    np.testing.assert_allclose(out[0, :100], 0.0, atol=1e-12)  # nothing before the echo
    np.testing.assert_allclose(out[1, 300:], -2 * kernel[: n - 300], atol=1e-12)  # linear, shift-invariant
    # a long echo at fr: its steady state is the echo times 1 + a e^(i phase), the tail's response at fr of
    # magnitude a (its phase the tail's own, from the sum over the kernel)
    m = 4000
    burst = np.zeros((1, m))
    burst[0, :2000] = np.sin(2 * np.pi * fr * np.arange(2000) * dt)
    rung = echo_ringing(burst, dt, f, np.random.default_rng(4))
    t = np.arange(m) * dt - 1 / f
    tail = np.where(t >= 0, np.sin(2 * np.pi * fr * t) * np.exp(-np.clip(t, 0, None) / tau), 0.0)
    h = np.sum(tail * np.exp(-2j * np.pi * fr * np.arange(m) * dt))
    assert np.abs(rung[0, 1500:2000]).max() == pytest.approx(abs(1 + a * h / abs(h)), rel=0.02)


def test_ringing_is_a_share_of_wall_records_drawn_apart():
    from gpr3d.simulation.surveys import SurveySource, survey_sample

    rung = sum(not np.array_equal(survey_sample(5, i, profile="wall", ringing=0.5)[0].data,
                                  survey_sample(5, i, profile="wall")[0].data) for i in range(8))
    assert 1 <= rung <= 7  # about half
    every = [survey_sample(5, i, profile="wall", ringing=1.0) for i in range(2)]
    for i, (s, lab) in enumerate(every):  # the labels and the records' other draws stay
        s0, lab0 = survey_sample(5, i, profile="wall")
        assert lab == lab0 and s.data.shape == s0.data.shape and not np.array_equal(s.data, s0.data)
    assert np.array_equal(SurveySource(5, profile="wall", ringing=1.0)(1)[0].data, every[1][0].data)
    for bad in (dict(profile="wall", ringing=1.5), dict(profile="train", ringing=0.5)):
        with pytest.raises(ValueError, match="ringing is a share"):
            SurveySource(5, **bad)


def test_a_wall_record_s_box_pad_changes_its_labels_times_and_nothing_else():
    from gpr3d.simulation.surveys import SurveySource, survey_sample

    s0, lab0 = survey_sample(5, 2, profile="wall")
    s1, lab1 = survey_sample(5, 2, profile="wall", box_pad=0.4)
    assert np.array_equal(s0.data, s1.data) and lab0["dt_s"] == lab1["dt_s"]
    f = s0.frequency_hz
    t_end = (lab0["n_samples"] - 1) * lab0["dt_s"]
    assert lab0["labels"]
    for a, b in zip(lab0["labels"], lab1["labels"]):
        assert a["apex_time_s"] == b["apex_time_s"] and a["box"][0::2] == b["box"][0::2]
        assert b["box"][1] == pytest.approx(max(a["apex_time_s"] - 0.4 / f, 0.0), rel=1e-9, abs=1e-15)
        if a["box"][3] < t_end:  # (not clipped by the record's end)
            assert a["box"][3] - b["box"][3] == pytest.approx(0.3 / f, rel=1e-6)
    assert SurveySource(5, profile="wall", box_pad=0.4)(2)[1] == lab1
    for bad in (-1.0, 3.0, float("inf"), "0.4"):
        with pytest.raises(ValueError, match="box_pad is the labels' time pad"):
            SurveySource(5, profile="wall", box_pad=bad)


def test_a_pad_in_the_drawn_wavelet_s_periods_follows_the_frequency_the_record_was_made_with(monkeypatch):
    """``pad_wavelet``: the box's pad is counted in periods of the wavelet the forward model was given (recorded
    here from its call), not of the label's frequency; the record and the boxes' traces stay."""
    import gpr3d.simulation.forward as fwd
    from gpr3d.simulation.surveys import SurveySource, survey_sample

    calls, real = [], fwd.forward_model

    def spy(*a, **kw):
        calls.append(kw["frequency_hz"])
        return real(*a, **kw)

    monkeypatch.setattr(fwd, "forward_model", spy)
    seen = set()
    for i in range(3):
        s0, lab0 = survey_sample(5, i, profile="wall")
        for pad in (None, 0.4):
            s1, lab1 = survey_sample(5, i, profile="wall", box_pad=pad, pad_wavelet=True)
            f_drawn, f = calls[-1], s1.frequency_hz
            seen.add(round(f_drawn / f, 6))
            assert np.array_equal(s0.data, s1.data)
            t_end = (lab1["n_samples"] - 1) * lab1["dt_s"]
            p = 0.7 if pad is None else pad
            for a, b in zip(lab0["labels"], lab1["labels"]):
                assert a["box"][0::2] == b["box"][0::2] and a["apex_time_s"] == b["apex_time_s"]
                assert b["box"][1] == pytest.approx(max(a["apex_time_s"] - p / f_drawn, 0.0), rel=1e-9, abs=1e-15)
                if a["box"][3] < t_end and b["box"][3] < t_end:
                    assert b["box"][3] - a["box"][3] == pytest.approx(p / f_drawn - 0.7 / f, rel=1e-6, abs=1e-15)
        assert SurveySource(5, profile="wall", pad_wavelet=True)(i)[1] == survey_sample(
            5, i, profile="wall", pad_wavelet=True)[1]
    assert len(seen) == 3 and all(0.8 <= r <= 1.2 for r in seen) and 1.0 not in seen  # (drawn, not the label's)
    # without augmentation the wavelet is the label's: the same boxes
    assert survey_sample(5, 0, profile="wall", augment=False, pad_wavelet=True)[1] == \
        survey_sample(5, 0, profile="wall", augment=False)[1]
