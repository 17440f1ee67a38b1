import numpy as np
import pytest

from gpr3d import GPR3DError, InvalidDataError, Survey
from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.units import C0


def make(n=10, m=20, **kw):
    return Survey(data=np.arange(n * m, dtype=np.float64).reshape(n, m), dt_s=0.1e-9, **kw)


def test_stores_float32_and_axes():
    s = make(t0_s=0.5e-9, eps_r=4.0)
    assert s.data.dtype == np.float32 and s.data.flags.c_contiguous
    assert s.shape == (10, 20) and len(s) == 10
    assert s.times_s[3] == pytest.approx(0.3e-9, rel=1e-9, abs=0)
    assert s.twt_s[5] == pytest.approx(0.0)
    # eps_r 4 -> v = c/2; 1 ns two-way -> 0.25 * c * 1e-9 m
    assert s.depths_m()[15] == pytest.approx(C0 / 2 * 1e-9 / 2)
    assert s.depths_m()[0] < 0


@pytest.mark.parametrize("kwargs, msg", [
    ({"data": np.zeros((0, 5))}, "zero traces"),
    ({"data": np.zeros((2, 1))}, "at least 2 samples"),
    ({"data": np.zeros((2, 3, 4))}, "2-D"),
    ({"data": np.array([[1.0, np.nan, 2.0]])}, "1 NaN/inf"),
    ({"data": np.zeros((2, 3)) + 1j}, "real numbers"),
    ({"dt_s": 0.0}, "dt_s must be > 0"),
    ({"dt_s": 0.1}, "implausible for GPR"),  # nanoseconds given as seconds
    ({"eps_r": 0.5}, "eps_r must be >= 1"),
    ({"positions_xyz": np.zeros((3, 3))}, r"shape \(2, 3\)"),
    ({"orientations_quat_wxyz": np.zeros((2, 4))}, "non-zero"),
    ({"timestamps_s": [0.0, np.inf]}, "NaN/inf"),
])
def test_validation_names_the_problem(kwargs, msg):
    base = {"data": np.zeros((2, 3)), "dt_s": 1e-10}
    base.update(kwargs)
    with pytest.raises(InvalidDataError, match=msg):
        Survey(**base)


def test_slicing_returns_surveys_with_per_trace_fields():
    s = make(positions_xyz=np.arange(30.0).reshape(10, 3), timestamps_s=np.arange(10.0),
             orientations_quat_wxyz=quat_from_yaw(np.linspace(0, 1, 10)))
    sub = s[2:8:2]
    assert isinstance(sub, Survey) and sub.n_traces == 3
    np.testing.assert_array_equal(sub.data, s.data[2:8:2])
    np.testing.assert_array_equal(sub.timestamps_s, [2, 4, 6])
    assert sub.headings_rad == pytest.approx(np.linspace(0, 1, 10)[2:8:2])
    assert sub.metadata["trace_index_source"] == [2, 4, 6]
    assert sub[1].metadata["trace_index_source"] == [4]  # indices compose back to the recording
    assert s[-1].n_traces == 1 and s[np.array([True] * 3 + [False] * 7)].n_traces == 3
    with pytest.raises(IndexError):
        s[10]
    with pytest.raises(InvalidDataError):
        s[5:5]


def test_equals_and_replace():
    s = make(frequency_hz=1e9)
    assert s.equals(s.copy())
    t = s.replace(frequency_hz=2e9)
    assert not s.equals(t) and s.frequency_hz == 1e9
    with pytest.raises(InvalidDataError, match="unknown Survey field"):
        s.replace(colour="red")


def test_distance_and_headings():
    pos = np.zeros((4, 3))
    pos[:, 0] = [0, 3, 3, 3]
    pos[:, 1] = [0, 0, 4, 4]
    s = make(n=4, positions_xyz=pos).with_headings(np.pi / 2)
    np.testing.assert_allclose(s.distances_m, [0, 3, 7, 7])
    np.testing.assert_allclose(s.headings_rad, np.pi / 2)


def test_the_methods_reach_io_and_processing_through_the_plugins(tmp_path, monkeypatch):
    """core imports neither io nor processing: gpr3d/__init__ names them, resolved on first use."""
    import gpr3d.core.survey as cs
    from gpr3d.core.survey import PLUGINS, register_plugin

    calls = []
    monkeypatch.setitem(PLUGINS, "save", lambda survey, path: calls.append(("save", survey.n_traces, path)))
    monkeypatch.setitem(PLUGINS, "step", "gpr3d.processing.dewow:dewow")  # resolved by name when first called
    s = Survey(data=np.ones((3, 8), np.float32), dt_s=1e-10)
    s.save(tmp_path / "a.h5")
    assert calls == [("save", 3, tmp_path / "a.h5")] and not (tmp_path / "a.h5").exists()
    from gpr3d.processing.dewow import dewow

    assert cs._plugin("step") is dewow and PLUGINS["step"] is dewow  # (imported once, then kept)
    monkeypatch.delitem(PLUGINS, "load")
    with pytest.raises(GPR3DError, match="no Survey 'load' plug-in"):
        Survey.load(tmp_path / "a.h5")
    with pytest.raises(ValueError, match="unknown Survey plug-in role 'write'"):
        register_plugin("write", print)
    with pytest.raises(ValueError, match="name it 'package.module:function'"):
        register_plugin("save", "gpr3d.io.hdf5.write_survey")
    # what gpr3d registers: HDF5 and the processing steps
    monkeypatch.undo()
    from gpr3d.io.hdf5 import read_survey
    from gpr3d.processing.steps import run_step

    assert cs._plugin("load") is read_survey and cs._plugin("step") is run_step
