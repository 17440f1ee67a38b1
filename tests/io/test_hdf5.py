import h5py
import numpy as np
import pytest

import gpr3d
from gpr3d import Survey
from gpr3d.core.errors import FormatError
from gpr3d.core.poses import quat_from_yaw
from gpr3d.io.hdf5 import read_surveys, write_survey, write_surveys
from tests.conftest import real_file


def full_survey(n=23, m=77, seed=1):
    rng = np.random.default_rng(seed)
    s = Survey(
        data=rng.standard_normal((n, m)).astype(np.float32) * 1e4,
        dt_s=0.1234e-9,
        t0_s=1.5e-9,
        timestamps_s=np.cumsum(rng.random(n)) + 1.7e9,
        positions_xyz=rng.standard_normal((n, 3)),
        orientations_quat_wxyz=quat_from_yaw(rng.uniform(-3, 3, n)),
        offset_m=0.05,
        frequency_hz=1.6e9,
        eps_r=7.25,
        metadata={"format": "test", "nested": {"a": [1, 2.5, None, "x"], "nan": float("nan")}, "ü": "unicode"},
    )
    return s.dewow().remove_background(method="median", window_traces=5)


def test_round_trip_is_exact(tmp_path):
    s = full_survey()
    s.save(tmp_path / "s.h5")
    back = Survey.load(tmp_path / "s.h5")
    # NaN != NaN in dicts: compare metadata through JSON, everything else exactly
    assert np.isnan(back.metadata["nested"].pop("nan")) and np.isnan(s.metadata["nested"].pop("nan"))
    assert back.equals(s)
    assert back.history[0]["step"] == "dewow" and back.history[1]["args"] == {"method": "median", "window_traces": 5}


def test_round_trip_minimal_and_real(tmp_path):
    bare = Survey(data=np.arange(12, dtype=np.float32).reshape(3, 4), dt_s=1e-10)
    write_survey(bare, tmp_path / "b.h5")
    assert gpr3d.read(tmp_path / "b.h5").equals(bare)  # detected by content
    real = gpr3d.read(real_file("gprpy_gssi_400MHz/FILE____032.DZT"))
    real.save(tmp_path / "r.h5")
    assert gpr3d.read(tmp_path / "r.h5").equals(real)


def test_multi_survey_file(tmp_path):
    a, b = full_survey(seed=1), full_survey(n=5, seed=2)
    for s in (a, b):
        s.metadata["nested"].pop("nan")
    write_surveys([a, b], tmp_path / "two.h5")
    back = read_surveys(tmp_path / "two.h5")
    assert back[0].equals(a) and back[1].equals(b)
    assert gpr3d.read(tmp_path / "two.h5", channel=1).equals(b)
    with pytest.raises(FormatError, match="channel 2 does not exist"):
        gpr3d.read(tmp_path / "two.h5", channel=2)


def test_newer_schema_is_refused(tmp_path):
    write_survey(full_survey(), tmp_path / "s.h5")
    with h5py.File(tmp_path / "s.h5", "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(FormatError, match="schema version 99"):
        read_surveys(tmp_path / "s.h5")


def test_nan_in_stored_data(tmp_path):
    write_survey(full_survey(), tmp_path / "s.h5")
    with h5py.File(tmp_path / "s.h5", "a") as f:
        f["surveys/0/data"][0, 0] = np.inf
    with pytest.raises(FormatError, match="NaN/inf"):
        read_surveys(tmp_path / "s.h5")


def test_truncated_h5(tmp_path):
    write_survey(full_survey(), tmp_path / "s.h5")
    raw = (tmp_path / "s.h5").read_bytes()
    (tmp_path / "cut.h5").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(FormatError):
        gpr3d.read(tmp_path / "cut.h5", format="gpr3d")


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    good = full_survey(seed=3)
    good.metadata["nested"].pop("nan")
    write_survey(good, tmp_path / "s.h5")

    class Boom(Exception):
        pass

    def explode(*a, **k):
        raise Boom

    monkeypatch.setattr("gpr3d.io.hdf5.json.dumps", explode)
    with pytest.raises(Boom):
        write_survey(full_survey(seed=4), tmp_path / "s.h5")
    monkeypatch.undo()
    assert read_surveys(tmp_path / "s.h5")[0].equals(good)
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]  # no temporary left behind
