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
    with pytest.raises(FormatError, match="^cut.h5: HDF5 content is corrupt or truncated"):
        gpr3d.read(tmp_path / "cut.h5", format="gpr3d")


def test_nan_in_metadata_and_history_is_stored(tmp_path):
    s = Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10, metadata={"gain": float("nan")},
               history=[{"step": "x", "result": {"t0_s": float("inf")}}])
    write_survey(s, tmp_path / "n.h5")
    back = read_surveys(tmp_path / "n.h5")[0]
    assert np.isnan(back.metadata["gain"]) and back.history[0]["result"]["t0_s"] == float("inf")


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


# ---------------------------------------------------------------- the file as written, and every refusal

from gpr3d.io.hdf5 import SCHEMA, SCHEMA_VERSION, is_gpr3d_h5, read_survey  # noqa: E402


def test_the_layout_on_disk(tmp_path):
    s = full_survey()
    s.metadata["nested"].pop("nan")
    write_survey(s, tmp_path / "s.h5")
    with h5py.File(tmp_path / "s.h5") as f:
        assert (f.attrs["schema"], int(f.attrs["schema_version"]), f.attrs["gpr3d_version"]) == \
            ("gpr3d.survey", 1, gpr3d.__version__)
        g = f["surveys/0"]
        d = g["data"]
        assert d.dtype == np.float32 and d.compression == "gzip" and d.compression_opts == 4 and d.shuffle
        np.testing.assert_array_equal(d[()], s.data)
        for name in ("timestamps_s", "positions_xyz", "orientations_quat_wxyz"):
            np.testing.assert_array_equal(g[name][()], getattr(s, name))
            assert g[name].dtype == np.float64
        assert {k: float(g.attrs[k]) for k in ("dt_s", "t0_s", "offset_m", "frequency_hz", "eps_r")} == \
            {"dt_s": s.dt_s, "t0_s": s.t0_s, "offset_m": 0.05, "frequency_hz": 1.6e9, "eps_r": 7.25}
        import json

        assert json.loads(g.attrs["metadata_json"]) == s.metadata
        assert json.loads(g.attrs["history_json"]) == s.history
    assert (SCHEMA, SCHEMA_VERSION) == ("gpr3d.survey", 1)


def test_a_bare_survey_stores_no_optional_fields(tmp_path):
    bare = Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10)
    write_survey(bare, tmp_path / "b.h5")
    with h5py.File(tmp_path / "b.h5") as f:
        g = f["surveys/0"]
        assert set(g) == {"data"} and set(g.attrs) == {"dt_s", "t0_s", "offset_m", "metadata_json", "history_json"}
    back = read_surveys(tmp_path / "b.h5")[0]
    assert back.frequency_hz is None and back.eps_r is None and back.positions_xyz is None
    assert back.t0_s == 0.0 and back.offset_m == 0.0


def test_missing_t0_and_offset_read_as_zero(tmp_path):
    write_survey(Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10, t0_s=1e-9, offset_m=0.1), tmp_path / "s.h5")
    with h5py.File(tmp_path / "s.h5", "a") as f:
        del f["surveys/0"].attrs["t0_s"], f["surveys/0"].attrs["offset_m"]
    back = read_surveys(tmp_path / "s.h5")[0]
    assert back.t0_s == 0.0 and back.offset_m == 0.0


def test_surveys_come_back_in_number_order(tmp_path):
    surveys = [Survey(data=np.full((2, 3), k, np.float32), dt_s=1e-10) for k in range(12)]
    write_surveys(surveys, tmp_path / "m.h5")
    assert [float(s.data[0, 0]) for s in read_surveys(tmp_path / "m.h5")] == list(range(12))  # 10 after 9
    assert float(read_survey(tmp_path / "m.h5", channel=11).data[0, 0]) == 11.0
    assert float(read_survey(tmp_path / "m.h5").data[0, 0]) == 0.0
    with pytest.raises(FormatError, match=r"^m.h5: has 12 survey\(s\); channel -1 does not exist$"):
        read_survey(tmp_path / "m.h5", channel=-1)
    with pytest.raises(FormatError, match=r"^m.h5: has 12 survey\(s\); channel 12 does not exist$"):
        read_survey(tmp_path / "m.h5", channel=12)


def _edit(path, fn):
    with h5py.File(path, "a") as f:
        fn(f)
    return path


@pytest.mark.parametrize("edit, message", [
    (lambda f: f.attrs.__setitem__("schema", "other.thing"),
     "s.h5: not a gpr3d survey file (schema attribute 'other.thing')"),
    (lambda f: f.attrs.__delitem__("schema"), "s.h5: not a gpr3d survey file (schema attribute None)"),
    (lambda f: f.attrs.__setitem__("schema_version", 2),
     "s.h5: written with schema version 2; this gpr3d reads up to 1: upgrade gpr3d"),
    (lambda f: f.attrs.__setitem__("schema_version", float("inf")),  # (the fuzzer's: once an OverflowError)
     "s.h5: header field schema_version = inf is not a whole number"),
    (lambda f: f.__delitem__("surveys"), "s.h5: holds no surveys"),
    (lambda f: f.__delitem__("surveys/0"), "s.h5: holds no surveys"),
    (lambda f: f["surveys/0"].__delitem__("data"), "s.h5: survey 0 has no data set 'data'"),
    (lambda f: (f["surveys/0"].__delitem__("data"), f["surveys/0"].create_dataset("data", data=np.ones((2, 3, 1)))),
     "s.h5: survey 0: data is a 3-D float64 data set, not a 2-D array of numbers"),
    (lambda f: (f["surveys/0"].__delitem__("data"), f["surveys/0"].create_dataset("data", data=np.array([[b"ab"]]))),
     "s.h5: survey 0: data is a 2-D |S2 data set, not a 2-D array of numbers"),
    (lambda f: f["surveys/0"].attrs.__delitem__("dt_s"), "s.h5: survey 0 has no dt_s attribute"),
    (lambda f: f["surveys/0"].attrs.__setitem__("metadata_json", "[1, 2]"),
     "s.h5: survey 0: its metadata_json holds a list, not an object"),
    (lambda f: f["surveys/0"].attrs.__setitem__("history_json", "null"),
     "s.h5: survey 0: its history_json holds null, not a list"),
    (lambda f: f["surveys/0"].attrs.__delitem__("metadata_json"), "s.h5: survey 0 is incomplete or corrupt"),
    (lambda f: f["surveys/0"].attrs.__setitem__("history_json", "{not json"), "s.h5: survey 0 is incomplete"),
    (lambda f: f["surveys/0"].attrs.__setitem__("dt_s", -1.0), "s.h5: survey 0: "),
])
def test_damaged_files_are_named(tmp_path, edit, message):
    write_survey(Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10), tmp_path / "s.h5")
    _edit(tmp_path / "s.h5", edit)
    with pytest.raises(FormatError) as e:
        read_surveys(tmp_path / "s.h5")
    assert str(e.value).startswith(message)


def test_an_older_or_missing_version_is_read(tmp_path):
    p = tmp_path / "s.h5"
    write_survey(Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10), p)
    _edit(p, lambda f: f.attrs.__delitem__("schema_version"))
    assert read_surveys(p)[0].n_traces == 2
    _edit(p, lambda f: f.attrs.__setitem__("schema_version", 1))
    assert read_surveys(p)[0].n_traces == 2


def test_is_gpr3d_h5(tmp_path):
    p = tmp_path / "s.h5"
    write_survey(Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10), p)
    assert is_gpr3d_h5(p)
    other = tmp_path / "o.h5"
    with h5py.File(other, "w") as f:
        f.attrs["schema"] = "gpr3d.volume"
    assert not is_gpr3d_h5(other)
    text = tmp_path / "t.h5"
    text.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)  # the signature, then nothing HDF5 can open
    assert not is_gpr3d_h5(text)
    assert not is_gpr3d_h5(tmp_path / "missing.h5")


def test_writing_nothing_is_refused(tmp_path):
    with pytest.raises(ValueError, match="^nothing to write: empty list of surveys$"):
        write_surveys([], tmp_path / "e.h5")
    assert not list(tmp_path.iterdir())


def test_a_declared_size_is_checked_against_the_file_before_anything_is_read(tmp_path, monkeypatch):
    from gpr3d.io import hdf5

    p = tmp_path / "z.h5"
    write_survey(Survey(data=np.zeros((256, 512), np.float32), dt_s=1e-10), p)  # 512 KiB of samples
    _edit(p, lambda f: (f["surveys/0"].__delitem__("data"),
                        f["surveys/0"].create_dataset("data", data=np.zeros((256, 512), np.float32),
                                                      compression="gzip")))
    size = p.stat().st_size
    ratio = 256 * 512 * 4 / size
    assert 1 < ratio < 64  # (gzip of zeros; the file's other parts count too)
    monkeypatch.setattr(hdf5, "_MAX_UNCHECKED_BYTES", 1000)
    assert read_surveys(p)[0].n_traces == 256  # compressed within the allowed ratio: read
    monkeypatch.setattr(hdf5, "_MAX_DECLARED_RATIO", ratio * 0.99)
    with pytest.raises(FormatError, match=rf"^z.h5: survey 0 declares a 256x512 data set \(0.000488 GiB\) in a "
                                          rf"{size:,}-byte file: truncated or corrupt$"):
        read_surveys(p)
    monkeypatch.setattr(hdf5, "_MAX_UNCHECKED_BYTES", 256 * 512 * 4)  # small data sets are never refused
    assert read_surveys(p)[0].n_traces == 256


@pytest.mark.parametrize("text, said", [('"text"', "a string"), ("5", "a number"), ("2.5", "a number"),
                                        ("true", "true/false"), ("{}", "an object")])
def test_every_json_kind_in_the_wrong_place_is_named(tmp_path, text, said):
    p = tmp_path / "s.h5"
    write_survey(Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10), p)
    _edit(p, lambda f: f["surveys/0"].attrs.__setitem__("history_json", text))
    with pytest.raises(FormatError) as e:
        read_surveys(p)
    assert str(e.value) == f"s.h5: survey 0: its history_json holds {said}, not a list"


def test_the_schema_attribute_as_bytes_or_as_an_array(tmp_path):
    p = tmp_path / "s.h5"
    write_survey(Survey(data=np.ones((2, 3), np.float32), dt_s=1e-10), p)
    _edit(p, lambda f: f.attrs.__setitem__("schema", np.bytes_(b"gpr3d.survey")))  # written by another HDF5 tool
    assert read_surveys(p)[0].n_traces == 2
    _edit(p, lambda f: f.attrs.__setitem__("schema", np.zeros(3)))
    with pytest.raises(FormatError) as e:
        read_surveys(p)
    assert str(e.value) == "s.h5: not a gpr3d survey file (schema attribute 'array([0., 0., 0.])')"
