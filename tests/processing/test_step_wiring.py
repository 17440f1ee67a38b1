"""Each processing step passes its arguments, and the survey's own facts (time zero, frequency, offset), to the array
function it wraps: the step's data against that function called by hand, defaults included."""

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0
from gpr3d.processing import (
    bandpass, dewow, envelope, estimate_time_zero, gain_agc, gain_sec, gain_tpow, remove_background, remove_dc,
    shift_traces,
)

DT = 0.1e-9


@pytest.fixture(scope="module")
def s():
    rng = np.random.default_rng(11)
    data = rng.standard_normal((12, 300)).astype(np.float32)
    data[:, 40] += 8.0  # a direct wave at 4 ns
    return Survey(data=data, dt_s=DT, t0_s=1.5e-9, frequency_hz=500e6, offset_m=0.3, eps_r=6.0)


CASES = [
    ("dewow", {}, lambda s: dewow(s.data, DT, 1 / 500e6)),
    ("dewow", {"window_s": 3e-9}, lambda s: dewow(s.data, DT, 3e-9)),
    ("remove_dc", {}, lambda s: remove_dc(s.data)),
    ("remove_dc", {"sample_range": [10, 50]}, lambda s: remove_dc(s.data, sample_range=(10, 50))),
    ("remove_background", {}, lambda s: remove_background(s.data)),
    ("remove_background", {"method": "median", "window_traces": 4},
     lambda s: remove_background(s.data, method="median", window_traces=4)),
    ("remove_background", {"window_traces": 5, "trailing": True},
     lambda s: remove_background(s.data, window_traces=5, trailing=True)),
    ("gain_tpow", {}, lambda s: gain_tpow(s.data, DT, power=1.0, t0_s=1.5e-9, t_ref_s=1e-9)),
    ("gain_tpow", {"power": 2.0, "t_ref_s": 3e-9}, lambda s: gain_tpow(s.data, DT, power=2.0, t0_s=1.5e-9, t_ref_s=3e-9)),
    ("gain_sec", {"alpha_per_s": 2e8}, lambda s: gain_sec(s.data, DT, alpha_per_s=2e8, power=1.0, t0_s=1.5e-9,
                                                          t_ref_s=1e-9, max_gain=1e6)),
    ("gain_sec", {"alpha_per_s": 2e8, "power": 0.5, "t_ref_s": 2e-9, "max_gain": 30.0},
     lambda s: gain_sec(s.data, DT, alpha_per_s=2e8, power=0.5, t0_s=1.5e-9, t_ref_s=2e-9, max_gain=30.0)),
    ("gain_sec", {"alpha_per_s": 3e9}, lambda s: gain_sec(s.data, DT, alpha_per_s=3e9, power=1.0, t0_s=1.5e-9,
                                                          t_ref_s=1e-9, max_gain=1e6)),  # the default cap bites
    ("gain_agc", {}, lambda s: gain_agc(s.data, DT, window_s=4 / 500e6, eps=1e-3)),
    ("gain_agc", {"window_s": 2e-9, "eps": 0.5}, lambda s: gain_agc(s.data, DT, window_s=2e-9, eps=0.5)),
    ("bandpass", {"fmin_hz": 1e8, "fmax_hz": 1e9, "order": 2}, lambda s: bandpass(s.data, DT, fmin_hz=1e8, fmax_hz=1e9,
                                                                                    order=2)),
    ("bandpass", {"fmax_hz": 1e9}, lambda s: bandpass(s.data, DT, fmax_hz=1e9)),
    ("envelope", {}, lambda s: envelope(s.data)),
]


@pytest.mark.parametrize("name, args, want", CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_a_step_is_its_function(s, name, args, want):
    out = s.apply(name, **args)
    assert out.data.dtype == np.float32
    np.testing.assert_array_equal(out.data, want(s))


def test_results_recorded(s):
    assert s.dewow().history[-1]["result"] == {"window_s": pytest.approx(2e-9, rel=1e-9, abs=0)}
    assert s.gain_agc().history[-1]["result"] == {"window_s": pytest.approx(8e-9, rel=1e-9, abs=0)}
    assert s.bandpass(fmax_hz=1e9).history[-1]["result"] == {"fmin_hz": None, "fmax_hz": 1e9}
    assert "result" not in s.remove_dc().history[-1]


def test_time_zero_step_by_hand(s):
    """t0 from the chosen method and options, less the air wave's offset / c, then cut (or only recorded)."""
    for kw in ({}, {"method": "peak"}, {"method": "peak", "search_s": 3e-9}, {"threshold": 0.5}):
        est = estimate_time_zero(s.data, DT, **{"method": "first_break", **kw})
        t0 = max(est - 0.3 / C0, 0.0)
        out = s.time_zero(**kw)
        assert out.history[-1]["result"]["t0_s"] == pytest.approx(t0, abs=1e-18), kw
        np.testing.assert_array_equal(out.data, shift_traces(s.data, t0 / DT))
        assert out.t0_s == 0.0
    kept = s.time_zero(method="peak", shift=False, offset_correction=False)
    assert kept.t0_s == pytest.approx(estimate_time_zero(s.data, DT, method="peak"), rel=1e-9, abs=0)
    np.testing.assert_array_equal(kept.data, s.data)
    per = s.time_zero(method="peak", per_trace=True)
    t0s = np.maximum(estimate_time_zero(s.data, DT, method="peak", per_trace=True) - 0.3 / C0, 0.0)
    assert per.history[-1]["result"]["t0_s"] == pytest.approx(float(np.median(t0s)), rel=1e-9, abs=0)
    np.testing.assert_array_equal(per.data, shift_traces(s.data, t0s / DT))
    with pytest.raises(InvalidDataError, match=r"^per_trace time zero needs shift=True \(one t0 per "
                                               r"survey otherwise\)$"):
        s.time_zero(per_trace=True, shift=False)


def test_steps_that_need_what_the_survey_lacks(s):
    bare = s.replace(frequency_hz=None, positions_xyz=None, eps_r=None)
    for step, words in (("dewow", "dewow: the survey has no centre frequency; give it explicitly"),
                        ("gain_agc", "gain_agc: the survey has no centre frequency"),
                        ("bandpass", "bandpass: the survey has no centre frequency"),
                        ("resample_spacing", "^resample_spacing needs trace positions \\(the survey has none\\)$"),
                        ("topo_correct", "^topo_correct needs trace positions with elevations \\(a track or GPS\\)$")):
        kw = {"spacing_m": 0.1} if step == "resample_spacing" else {}
        with pytest.raises(InvalidDataError, match=words):
            bare.apply(step, **kw)
    flat = s.replace(eps_r=None, positions_xyz=np.c_[np.arange(12) * 0.1, np.zeros(12), np.zeros(12)])
    with pytest.raises(InvalidDataError, match=r"^topo_correct: give eps_r or velocity_m_s \(the survey has no eps_r\)$"):
        flat.apply("topo_correct")
    assert flat.resample_spacing(spacing_m=0.2).history[-1]["result"] == {"n_traces": 6}
