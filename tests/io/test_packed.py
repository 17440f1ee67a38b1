"""The packed-dataset reader against files written here by hand with h5py (not by the simulator's writer), and
``gpr3d simulate`` folders: every field of every record, the padding of ragged records, and the errors."""

import json

import h5py
import numpy as np
import pytest

from gpr3d.core.errors import FormatError
from gpr3d.io.packed import SCHEMA, PackedDataset, labelled_records


def _scene(k):
    return {"x_start_m": 0.5 + k, "trace_step_m": 0.01 * (k + 1), "antenna": {"offset_m": 0.05 * k,
            "frequency_hz": 4e8 + 1e8 * k}, "medium": {"eps_r": 4.0 + k}, "tag": f"scene {k}"}


def _labels(k):
    return {"index": 10 + k, "eps_r": 4.0 + k, "labels": [{"kind": "rebar", "box": [k, 1e-9, k + 3, 2e-9]}]}


LENGTHS = (5, 3, 4)  # traces per record: ragged, zero-padded to 5 in the file


def write_packed(path, *, n_traces=True, schema=SCHEMA):
    rng = np.random.default_rng(1)
    data = np.zeros((3, 5, 6), np.float16)
    for k, n in enumerate(LENGTHS):
        data[k, :n] = rng.uniform(-1, 1, (n, 6)).astype(np.float16)
    s = h5py.string_dtype("utf-8")
    with h5py.File(path, "w") as f:
        f.attrs["schema"] = schema
        f.attrs["manifest_json"] = json.dumps({"seed": 7})
        f.attrs["config_json"] = json.dumps({"n_samples": 6})
        f.attrs["regenerate"] = "gpr3d simulate --n 3"
        f["data"] = data
        f["scale"] = np.array([2.0, 0.5, 3.0], np.float32)
        f["dt_s"] = np.array([1e-10, 2e-10, 5e-11])
        f["index"] = np.array([10, 11, 12], np.int64)
        if n_traces:
            f["n_traces"] = np.array(LENGTHS, np.int64)
        f.create_dataset("scene_json", data=np.array([json.dumps(_scene(k)) for k in range(3)], dtype=object), dtype=s)
        f.create_dataset("labels_json", data=np.array([json.dumps(_labels(k)) for k in range(3)], dtype=object),
                         dtype=s)
    return data


def test_every_field_of_every_record(tmp_path):
    p = tmp_path / "set.h5"
    data = write_packed(p)
    ds = PackedDataset(p)
    assert len(ds) == 3 and ds.manifest == {"seed": 7} and ds.config == {"n_samples": 6}
    assert ds.regenerate == "gpr3d simulate --n 3" and ds.shape == (3, 5, 6)
    assert ds.n_traces.tolist() == list(LENGTHS)
    for k, (scale, dt) in enumerate([(2.0, 1e-10), (0.5, 2e-10), (3.0, 5e-11)]):
        s, lab = ds[k]
        n = LENGTHS[k]
        assert s.data.dtype == np.float32 and s.data.shape == (n, 6)  # the padding is cut off
        np.testing.assert_array_equal(s.data, data[k, :n].astype(np.float32) * np.float32(scale))
        np.testing.assert_array_equal(ds.array(k), s.data)
        assert s.dt_s == dt
        sc = _scene(k)
        np.testing.assert_allclose(s.positions_xyz[:, 0], sc["x_start_m"] + sc["trace_step_m"] * np.arange(n),
                                   rtol=1e-12, atol=0)
        assert not s.positions_xyz[:, 1:].any()
        assert (s.offset_m, s.frequency_hz, s.eps_r) == (0.05 * k, 4e8 + 1e8 * k, 4.0 + k)
        assert s.metadata["format"] == "packed" and s.metadata["index"] == 10 + k
        assert s.metadata["path"] == str(p) and s.metadata["scene"] == sc
        assert lab == _labels(k) and ds.labels(k) == lab and ds.scene_dict(k) == sc


def test_negative_indices_count_from_the_end_and_others_are_refused(tmp_path):
    p = tmp_path / "set.h5"
    write_packed(p)
    ds = PackedDataset(p)
    assert ds[-1][1] == _labels(2) and ds[-3][1] == _labels(0)
    for bad in (3, -4):
        with pytest.raises(IndexError):
            ds[bad]


def test_without_lengths_every_record_has_the_full_width(tmp_path):
    p = tmp_path / "set.h5"
    write_packed(p, n_traces=False)
    ds = PackedDataset(p)
    assert ds.n_traces.tolist() == [5, 5, 5] and ds[1][0].data.shape == (5, 6)


def test_labelled_records_first_and_last_n(tmp_path):
    p = tmp_path / "set.h5"
    write_packed(p)
    idx = [lab["index"] for _, lab in labelled_records(p)]
    assert idx == [10, 11, 12]
    assert [lab["index"] for _, lab in labelled_records(p, n=2)] == [10, 11]
    assert [lab["index"] for _, lab in labelled_records(p, n=2, last=True)] == [11, 12]
    assert [s.n_traces for s, _ in labelled_records(p, n=1, last=True)] == [4]


def test_not_a_packed_dataset(tmp_path):
    p = tmp_path / "other.h5"
    write_packed(p, schema="something.else")
    with pytest.raises(FormatError, match="^other.h5: not a gpr3d packed dataset$"):
        PackedDataset(p)
    with pytest.raises(FormatError, match="^none.h5: no such file$"):
        PackedDataset(tmp_path / "none.h5")


def _folder(tmp_path, n=3):
    from gpr3d.core.survey import Survey

    root = tmp_path / "sim"
    for k in range(n):
        d = root / "samples" / f"{k:06d}"
        d.mkdir(parents=True)
        Survey(data=np.full((4, 8), k + 1.0, np.float32), dt_s=1e-10).save(d / "bscan.h5")
        (d / "labels.json").write_text(json.dumps(_labels(k)))
    (root / "samples" / "notes").mkdir()  # not a sample: left alone
    return root


def test_a_simulate_folder_in_index_order(tmp_path):
    root = _folder(tmp_path)
    got = list(labelled_records(root))
    assert [lab["index"] for _, lab in got] == [10, 11, 12]
    assert [float(s.data[0, 0]) for s, _ in got] == [1.0, 2.0, 3.0]
    assert [lab["index"] for _, lab in labelled_records(root, n=2)] == [10, 11]
    assert [lab["index"] for _, lab in labelled_records(root, n=1, last=True)] == [12]


def test_a_folder_without_samples_or_labels_is_named(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(FormatError, match="^empty: no samples/NNNNNN folders: not a gpr3d simulate dataset$"):
        list(labelled_records(tmp_path / "empty"))
    (tmp_path / "empty" / "samples").mkdir()
    with pytest.raises(FormatError, match="^empty: no samples/NNNNNN folders"):
        list(labelled_records(tmp_path / "empty"))
    root = _folder(tmp_path)
    (root / "samples" / "000001" / "labels.json").unlink()
    with pytest.raises(FormatError, match="^000001: sample folder has no labels.json$"):
        list(labelled_records(root))


def test_a_damaged_packed_file_is_named_and_defaults_are_kept(tmp_path):
    p = tmp_path / "set.h5"
    write_packed(p)
    with h5py.File(p, "a") as f:
        del f.attrs["regenerate"]
    assert PackedDataset(p).regenerate == ""
    with h5py.File(p, "a") as f:
        del f["scale"]
    with pytest.raises(FormatError, match=r"^set.h5: "):
        PackedDataset(p)


def test_an_index_past_the_end_is_named():
    class Three(PackedDataset):
        def __init__(self):
            self.index = [0, 1, 2]

    with pytest.raises(IndexError, match="^7$"):
        Three()[7]


def test_last_without_a_count_is_every_record(tmp_path):
    root = _folder(tmp_path)
    assert [lab["index"] for _, lab in labelled_records(root, last=True)] == [10, 11, 12]
    p = tmp_path / "set.h5"
    write_packed(p)
    assert [lab["index"] for _, lab in labelled_records(p, last=True)] == [10, 11, 12]
