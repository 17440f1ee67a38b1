"""gpr3d.pipeline's first stages against the library calls they stand for, value by value."""

import numpy as np
import pytest

import gpr3d
from gpr3d import Survey
from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.io.trajectory import Trajectory, write_tum
from gpr3d.pipeline import SURVEY_SUFFIXES, apply_steps, attach_trajectory, place_traces, read_recording, write_survey

DZT = __import__("pathlib").Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT"


def test_read_recording_places_and_processes_as_the_library_does():
    from gpr3d.core.gridsurvey import place_by_marks

    s = read_recording(DZT, steps=["time_zero", "dewow", "gain_tpow:power=1.5"])
    ref = gpr3d.read(DZT).time_zero().dewow().gain_tpow(power=1.5)
    np.testing.assert_array_equal(s.data, ref.data)
    assert [h["step"] for h in s.history] == ["time_zero", "dewow", "gain_tpow"]
    placed = read_recording(DZT, marks_every_m=2.0, marks=[0, 500, 1000])
    want = place_by_marks(gpr3d.read(DZT), 2.0, marks=[0, 500, 1000])
    np.testing.assert_array_equal(placed.positions_xyz, want.positions_xyz)
    assert placed.positions_xyz[500, 0] == pytest.approx(2.0)  # the second mark two metres on


def test_steps_apply_in_the_order_given_and_unknown_ones_are_refused():
    s = Survey(data=np.random.default_rng(0).normal(size=(6, 50)), dt_s=1e-10, frequency_hz=1e9)
    a = apply_steps(s, ["dewow", "remove_background"])
    b = apply_steps(s, ["remove_background", "dewow"])
    np.testing.assert_allclose(a.data, s.dewow().remove_background().data)
    assert [h["step"] for h in b.history] == ["remove_background", "dewow"]
    assert apply_steps(s, []) is s and apply_steps(s, None) is s
    with pytest.raises(GPR3DError, match="nosuch"):
        apply_steps(s, ["nosuch"])


def test_a_track_places_each_trace_on_it_by_its_distance_along_the_line(tmp_path):
    x = 0.5 * np.arange(5)
    s = Survey(data=np.zeros((5, 20)), dt_s=1e-10, positions_xyz=np.c_[x, 0 * x, 0 * x])
    (tmp_path / "track.txt").write_text("0 1 0\n1 1 0\n1 2 0\n")  # two metres with a right-angle bend
    placed = place_traces(s, track=tmp_path / "track.txt")
    np.testing.assert_allclose(placed.positions_xyz[:, :2], [[0, 1], [0.5, 1], [1, 1], [1, 1.5], [1, 2]], atol=1e-9)
    assert place_traces(s) is s


def test_written_surveys_read_back_and_other_suffixes_are_refused(tmp_path):
    s = read_recording(DZT)[:40]
    write_survey(s, tmp_path / "a.h5")
    np.testing.assert_array_equal(gpr3d.read(tmp_path / "a.h5").data, s.data)
    write_survey(s, tmp_path / "a.sgy")
    np.testing.assert_allclose(gpr3d.read(tmp_path / "a.sgy").data, s.data, rtol=1e-6)
    write_survey(s, tmp_path / "a.png")
    assert (tmp_path / "a.png").read_bytes()[:4] == b"\x89PNG"
    assert ".png" in SURVEY_SUFFIXES and ".txt" not in SURVEY_SUFFIXES
    with pytest.raises(GPR3DError, match=r"a.txt: unknown output type '.txt'"):
        write_survey(s, tmp_path / "a.txt")


def test_a_trajectory_gives_one_pose_per_trace_or_one_line(tmp_path):
    s = Survey(data=np.zeros((4, 10)), dt_s=1e-10)
    tr = Trajectory([0, 1, 2, 3], [[0, 0, 0], [0.1, 0, 0], [0.2, 0.1, 0], [0.3, 0.2, 0]], [[1, 0, 0, 0]] * 4)
    write_tum(tr, tmp_path / "a.tum")
    got = attach_trajectory(s, tmp_path / "a.tum")
    np.testing.assert_allclose(got.positions_xyz, tr.positions_xyz)
    write_tum(Trajectory(tr.timestamps_s[:3], tr.positions_xyz[:3], tr.orientations_quat_wxyz[:3]), tmp_path / "b.tum")
    with pytest.raises((GPR3DError, InvalidDataError), match=r"b.tum holds 3 poses but line.h5 has 4 traces"):
        attach_trajectory(s, tmp_path / "b.tum", source="line.h5")
