import numpy as np
import pytest

import gpr3d
from gpr3d.core.poses import quat_from_yaw
from gpr3d.processing.steps import STEPS, describe_steps, parse_step
from gpr3d.simulation.synthetic import point_targets_bscan


def test_every_step_records_provenance_and_leaves_the_input_alone():
    s = point_targets_bscan([[0.4, 0.3]], n_traces=60)
    pos = s.positions_xyz.copy()
    pos[:, 2] = np.linspace(0.0, 0.05, 60)  # a slope, for the static correction to correct
    s = s.replace(positions_xyz=pos)
    before = s.data.copy()
    args = {"gain_sec": {"alpha_per_s": 1e8}, "resample_spacing": {"spacing_m": 0.02}}
    for name in STEPS:
        out = s.apply(name, **args.get(name, {}))
        assert out.history[-1]["step"] == name
        assert out.history[-1]["args"] == args.get(name, {})
        assert out.history[-1]["gpr3d"] == gpr3d.__version__
        assert out is not s
        # the survey carries what the step made: its data (changed: every step changes this record), its time zero
        # and its result, as the step itself gives them
        changes, result = STEPS[name](s, **args.get(name, {}))
        np.testing.assert_array_equal(out.data, np.asarray(changes.get("data", s.data), np.float32))
        assert out.data.shape != s.data.shape or not np.array_equal(out.data, s.data), name
        assert out.t0_s == changes.get("t0_s", s.t0_s)
        assert out.history[-1].get("result") == result
    np.testing.assert_array_equal(s.data, before)
    assert s.history == []


def test_chained_methods():
    s = point_targets_bscan([[0.4, 0.3]])
    p = s.time_zero().dewow().remove_background().gain_tpow(power=1.5).bandpass().envelope()
    assert [h["step"] for h in p.history] == ["time_zero", "dewow", "remove_background", "gain_tpow",
                                               "bandpass", "envelope"]
    assert p.history[1]["result"]["window_s"] == pytest.approx(1 / 800e6, rel=1e-9, abs=0)


def test_resample_spacing_interpolates_poses():
    s = point_targets_bscan([[0.4, 0.3]], n_traces=11, trace_step_m=0.03)
    s = s.with_headings(np.linspace(0, 1, 11)).replace(timestamps_s=np.arange(11) * 0.1)
    r = s.resample_spacing(spacing_m=0.015)
    assert r.n_traces == 21
    np.testing.assert_allclose(r.positions_xyz[:, 0], np.arange(21) * 0.015, atol=1e-12)
    np.testing.assert_allclose(r.headings_rad, np.linspace(0, 1, 21), atol=1e-9)
    np.testing.assert_allclose(r.timestamps_s, np.arange(21) * 0.05, atol=1e-12)


def test_parse_step_and_errors():
    assert parse_step("bandpass:fmin_hz=1e8:fmax_hz=9e8") == ("bandpass", {"fmin_hz": 1e8, "fmax_hz": 9e8})
    assert parse_step("remove_dc:sample_range=0,50") == ("remove_dc", {"sample_range": [0, 50]})
    assert parse_step("remove_background:method=median:window_traces=none")[1] == {"method": "median",
                                                                                 "window_traces": None}
    with pytest.raises(gpr3d.InvalidDataError, match="unknown processing step 'wiggle'"):
        parse_step("wiggle")
    with pytest.raises(gpr3d.InvalidDataError, match="expected key=value"):
        parse_step("dewow:5")
    s = point_targets_bscan([[0.4, 0.3]])
    with pytest.raises(gpr3d.InvalidDataError, match="dewow: .*unexpected keyword"):
        s.apply("dewow", windw=3)
    with pytest.raises(gpr3d.InvalidDataError, match="no centre frequency"):
        s.replace(frequency_hz=None).dewow()
    assert "time_zero" in describe_steps()


def test_resample_needs_positions():
    s = gpr3d.Survey(data=np.zeros((4, 10)), dt_s=1e-10, orientations_quat_wxyz=quat_from_yaw(np.zeros(4)))
    with pytest.raises(gpr3d.InvalidDataError, match="needs trace positions"):
        s.resample_spacing(spacing_m=0.1)
