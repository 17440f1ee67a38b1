"""Step arguments as the CLI gives them (text) and as Python gives them: parsed, typed and checked, each refusal
a one-line error naming the step and the argument."""

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import InvalidDataError
from gpr3d.processing.steps import STEPS, check_step_args, describe_steps, parse_step, run_step

N = 100


@pytest.fixture(scope="module")
def s():
    pos = np.c_[np.arange(10) * 0.1, np.zeros(10), np.r_[np.zeros(5), np.full(5, 3.0)]]  # a 3 m step in height
    return Survey(data=np.random.default_rng(0).standard_normal((10, N)).astype(np.float32), dt_s=0.1e-9,
                  frequency_hz=500e6, positions_xyz=pos, eps_r=9.0)


@pytest.mark.parametrize("text, want", [
    ("time_zero:shift=yes:per_trace=OFF", ("time_zero", {"shift": True, "per_trace": False})),
    ("time_zero:shift=TRUE", ("time_zero", {"shift": True})),
    ("time_zero:search_s=none:method=peak", ("time_zero", {"search_s": None, "method": "peak"})),
    ("time_zero:search_s=NULL", ("time_zero", {"search_s": None})),
    ("remove_dc:sample_range=[3, 40]", ("remove_dc", {"sample_range": [3, 40]})),
    ("remove_dc:sample_range=3,40", ("remove_dc", {"sample_range": [3, 40]})),
    ("bandpass:order=2.0", ("bandpass", {"order": 2})),
    ("gain_tpow:power=1.5e0", ("gain_tpow", {"power": 1.5})),
    ("envelope", ("envelope", {})),
])
def test_cli_text_is_parsed_and_typed(s, text, want):
    name, kwargs = parse_step(text)
    assert name == want[0]
    checked = check_step_args(s, name, kwargs)
    assert checked == want[1]
    assert [type(v) for v in checked.values()] == [type(v) for v in want[1].values()]


def test_parse_step_by_hand():
    assert parse_step("time_zero:method=peak:threshold=0.2") == ("time_zero", {"method": "peak", "threshold": 0.2})
    assert parse_step("dewow:window_s=a=b")[1] == {"window_s": "a=b"}  # split at the first '=' only
    with pytest.raises(InvalidDataError, match=r"^step argument 'power' given twice in 'gain_tpow:power=1: power=2'$"):
        parse_step("gain_tpow:power=1: power=2")
    assert parse_step("remove_dc:sample_range=[ ]")[1] == {"sample_range": []}
    assert parse_step("time_zero:shift=False")[1] == {"shift": False}
    assert parse_step("remove_dc:sample_range=[3")[1] == {"sample_range": "[3"}  # no closing bracket: not a list
    assert parse_step("remove_dc:sample_range=3]")[1] == {"sample_range": "3]"}
    with pytest.raises(InvalidDataError, match=r"^bad step argument 'window' in 'dewow:window': expected key=value$"):
        parse_step("dewow:window")
    with pytest.raises(InvalidDataError, match=r"^unknown processing step 'dwow'; known: time_zero, dewow, remove_dc, "):
        parse_step("dwow")
    with pytest.raises(InvalidDataError, match=r"^unknown processing step 'dwow'; known: time_zero, dewow, remove_dc, "):
        run_step(Survey(data=np.zeros((2, 8)), dt_s=1e-9), "dwow")


@pytest.mark.parametrize("step, kwargs, words", [
    ("gain_tpow", {"power": None}, "^gain_tpow: power must be given \\(not none\\)$"),
    ("time_zero", {"shift": "maybe"}, "^time_zero: shift must be true or false, got 'maybe'$"),
    ("bandpass", {"order": 2.5}, "^bandpass: order must be a whole number, got 2.5$"),
    ("bandpass", {"order": True}, "^bandpass: order must be a finite number, got True$"),
    ("gain_tpow", {"power": "abc"}, "^gain_tpow: power must be a finite number, got 'abc'$"),
    ("gain_tpow", {"power": float("inf")}, "^gain_tpow: power must be a finite number, got inf$"),
    ("remove_background", {"method": 5}, "^remove_background: method must be a word, got 5$"),
    ("remove_dc", {"sample_range": [1, 1]}, "^remove_dc: sample_range must satisfy 0 <= start < stop <= 100 \\(the "
                                            "samples per trace\\), got \\[1, 1\\]$"),
    ("remove_dc", {"sample_range": [-1, 5]}, "must satisfy 0 <= start"),
    ("remove_dc", {"sample_range": [0, 101]}, "must satisfy 0 <= start"),
    ("remove_dc", {"sample_range": [True, 5]}, "^remove_dc: sample_range must be two whole sample indices \\[start, "
                                               "stop\\], got \\[True, 5\\]$"),
    ("remove_dc", {"sample_range": [0.5, 5]}, "two whole sample indices"),
    ("remove_dc", {"sample_range": [1, 2, 3]}, "two whole sample indices"),
    ("remove_dc", {"sample_range": 5}, "two whole sample indices"),
    ("bandpass", {"fmin_hz": 5e8, "fmax_hz": 5e8}, "^bandpass: fmin_hz must be below fmax_hz, got 500000000.0 and "
                                                   "500000000.0$"),
    ("dewow", {"window": 1e-9}, "^dewow: got an unexpected keyword argument 'window'$"),
    ("time_zero", {"search_s": 10.0001e-9}, "^time_zero: search_s must be positive and at most the record's length"),
    ("resample_spacing", {"spacing_m": 0.0044}, "give at most 20 times the traces"),
    ("remove_dc", {"sample_range": "[3"}, "^remove_dc: sample_range must be two whole sample indices \\[start, "
                                          "stop\\], got '\\[3'$"),
])
def test_refusals_name_the_step_and_argument(s, step, kwargs, words):
    with pytest.raises(InvalidDataError, match=words):
        check_step_args(s, step, kwargs)


def test_an_array_functions_refusal_names_the_step(s):
    with pytest.raises(InvalidDataError, match=r"^bandpass: fmin_hz = 0.5 Hz must lie between the lowest frequency"):
        run_step(s, "bandpass", fmin_hz=0.5)


def test_limits_that_are_allowed(s):
    assert check_step_args(s, "remove_dc", {"sample_range": (0, N)}) == {"sample_range": [0, N]}
    assert check_step_args(s, "remove_dc", {"sample_range": [0.0, 5.0]}) == {"sample_range": [0, 5]}
    assert check_step_args(s, "time_zero", {"search_s": 10e-9}) == {"search_s": 10e-9}  # the whole record
    # the path runs 0.9 m along the ground (the 3 m rise in height is not path): 0.0046 m gives 196 <= 201 traces
    assert check_step_args(s, "resample_spacing", {"spacing_m": 0.0046}) == {"spacing_m": 0.0046}
    bare = s.replace(positions_xyz=None)  # no path: the rule has nothing to refuse, the step says what is missing
    assert check_step_args(bare, "resample_spacing", {"spacing_m": 1e-6}) == {"spacing_m": 1e-6}


def test_describe_steps_lists_each_with_its_arguments():
    lines = describe_steps().split("\n")
    assert len(lines) == len(STEPS)
    assert "  envelope  Hilbert envelope (instantaneous amplitude)." in lines
    assert "  dewow[:window_s]  Running-mean dewow; ``window_s`` defaults to one period of the centre frequency." in lines
    assert lines[0].startswith("  time_zero[:method,threshold,search_s,per_trace,shift,offset_correction]  Estimate")


def test_topo_correct_by_hand(s):
    """Traces 5-9 stand 3 m higher; with eps_r 9 (v = c/3) the low ones are delayed by 2 x 3 m / v = 60.04 ns
    (601 samples of 0.1 ns, rounded up); eps_r given beats the survey's; velocity beats both."""
    v = 299792458.0 / 3
    delay = 2 * 3.0 / v
    out = s.apply("topo_correct")
    n_extra = int(np.ceil(delay / 0.1e-9))
    assert out.n_samples == N + n_extra
    res = out.history[-1]["result"]
    assert res == {"datum_elevation_m": 3.0, "max_delay_s": pytest.approx(delay, rel=1e-9, abs=0),
                   "velocity_m_s": pytest.approx(v, rel=1e-9, abs=0)}
    np.testing.assert_allclose(out.data[5:, :N], s.data[5:], atol=1e-6)  # the high traces keep their times
    assert np.abs(out.data[:5, : n_extra - 1]).max() == 0.0  # the low ones start later
    v4 = s.apply("topo_correct", eps_r=4.0).history[-1]["result"]["velocity_m_s"]
    assert v4 == pytest.approx(299792458.0 / 2)
    assert s.apply("topo_correct", eps_r=4.0, velocity_m_s=1e8).history[-1]["result"]["velocity_m_s"] == 1e8
    # a whole number of samples: 2 x 0.15 m at 1e8 m/s = 3 ns = 30 samples, no extra sample
    flat = s.replace(positions_xyz=np.c_[s.positions_xyz[:, :2], np.r_[np.zeros(5), np.full(5, 0.15)]])
    assert flat.apply("topo_correct", velocity_m_s=1e8).n_samples == N + 30
    tall = s.replace(positions_xyz=np.c_[s.positions_xyz[:, :2], np.r_[np.zeros(5), np.full(5, 40.0)]])
    with pytest.raises(InvalidDataError, match=r"^topo_correct: 40.0 m of relief would lengthen the record 80-fold: "
                                               r"are the elevations in metres\?$"):
        tall.apply("topo_correct")
