"""The detections file (CONVENTIONS.md): what ``gpr3d detect`` writes and ``reconstruct --boxes`` reads."""

import json
import os
import stat

import numpy as np
import pytest

from gpr3d.core.atomic import atomic_path, atomic_write_text
from gpr3d.core.errors import FormatError
from gpr3d.io.detections import read_boxes, read_detections, write_detections

ONE = {"input": "line.DZT", "n_traces": 40, "dt_s": 1e-10, "channel": 0,
       "permittivity": {"eps_r": 6.5, "sigma": 0.3},
       "targets": [{"box": [3, 1e-9, 9, 4e-9], "score": 0.9, "apex_trace": 6, "apex_time_s": 2e-9, "depth_m": 0.1,
                    "x_m": 0.12, "custom": [1, 2]},
                   {"box": [20, 2e-9, 30, 5e-9], "score": 1}]}


def test_one_channel_round_trip_keeps_every_field(tmp_path):
    p = tmp_path / "d.json"
    write_detections([ONE], p)
    raw = json.loads(p.read_text())
    assert raw == ONE  # one channel: one object, not a list
    assert p.read_text().startswith('{\n "input"')  # indented by one
    assert read_detections(p) == [ONE]
    assert read_boxes(p) == [[3, 1e-9, 9, 4e-9], [20, 2e-9, 30, 5e-9]]


def test_several_channels_are_a_list_and_numpy_values_are_plain(tmp_path):
    two = [dict(ONE, channel=0), {"input": "x", "channel": 1, "n_traces": np.int64(5), "dt_s": np.float32(0.5),
                                  "targets": [{"box": np.array([1, 2.0, 3, 4.0]), "score": np.float64(0.25)}]}]
    p = tmp_path / "d.json"
    write_detections(two, p)
    raw = json.loads(p.read_text())
    assert isinstance(raw, list) and len(raw) == 2
    assert raw[1] == {"input": "x", "channel": 1, "n_traces": 5, "dt_s": 0.5,
                      "targets": [{"box": [1.0, 2.0, 3.0, 4.0], "score": 0.25}]}
    chans = read_detections(p)
    assert [c["channel"] for c in chans] == [0, 1]
    assert read_boxes(p, channel=1) == [[1.0, 2.0, 3.0, 4.0]]
    with pytest.raises(FormatError, match=r"^d.json: has 2 channel\(s\); no channel 2$"):
        read_boxes(p, channel=2)
    with pytest.raises(FormatError, match="no channel -1"):
        read_boxes(p, channel=-1)


def test_bare_lists_of_boxes(tmp_path):
    p = tmp_path / "b.json"
    p.write_text("[[1, 2e-9, 3, 4e-9], {\"box\": [5, 1e-9, 6, 2e-9], \"score\": 0.5}]")
    assert read_detections(p) == [{"targets": [{"box": [1, 2e-9, 3, 4e-9]},
                                               {"box": [5, 1e-9, 6, 2e-9], "score": 0.5}]}]
    assert read_boxes(p) == [[1, 2e-9, 3, 4e-9], [5, 1e-9, 6, 2e-9]]
    p.write_text("[]")
    assert read_detections(p) == [{"targets": []}] and read_boxes(p) == []
    p.write_text('{"targets": []}')
    assert read_boxes(p) == []


@pytest.mark.parametrize("text, message", [
    ("{not json", "d.json: cannot read detections: "),
    ('{"boxes": [[1, 2, 3, 4]]}', "d.json: no 'targets' list (expected gpr3d detect output, or a list of boxes)"),
    ('{"targets": {"box": [1, 2, 3, 4]}}', "d.json: no 'targets' list"),
    ('{"targets": [{"score": 1}]}', "d.json: target 0 has no 'box'"),
    ('{"targets": [{"box": [1, 2, 3, 4]}, [1, 2, 3, 4]]}', "d.json: target 1 has no 'box'"),
    ('{"targets": [{"box": [1, 2, 3, 4], "score": "high"}]}', "d.json: target 0 has a bad score 'high'"),
    ('{"targets": [{"box": [1, 2, 3, 4], "score": NaN}]}', "d.json: target 0 has a bad score nan"),
    ('[{"targets": []}, {"targets": [{"box": [1, 2, 3, 4], "score": Infinity}]}]',
     "d.json: channel 1: target 0 has a bad score inf"),
    ('[{"targets": []}, {"targets": "none"}]', "d.json: channel 1: no 'targets' list"),
    ('"a string"', "d.json: expected an object with a 'targets' list"),
    ("3", "d.json: expected an object with a 'targets' list"),
])
def test_bad_files_are_one_line_naming_the_problem(tmp_path, text, message):
    p = tmp_path / "d.json"
    p.write_text(text)
    with pytest.raises(FormatError) as e:
        read_detections(p)
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


def test_a_missing_file(tmp_path):
    with pytest.raises(FormatError, match="^missing.json: cannot read detections: "):
        read_detections(tmp_path / "missing.json")


def test_a_score_may_be_left_out_or_whole(tmp_path):
    p = tmp_path / "d.json"
    p.write_text('{"targets": [{"box": [1, 2, 3, 4]}, {"box": [1, 2, 3, 4], "score": 0}]}')
    assert len(read_detections(p)[0]["targets"]) == 2


# ---------------------------------------------------------------- atomic writes

def test_atomic_write_replaces_in_one_step_with_ordinary_permissions(tmp_path):
    p = tmp_path / "sub" / "out.txt"  # the folder is made
    atomic_write_text(p, "first ü")
    assert p.read_text(encoding="utf-8") == "first ü"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask  # not mkstemp's 0600
    atomic_write_text(p, "second")
    assert p.read_text() == "second" and sorted(x.name for x in p.parent.iterdir()) == ["out.txt"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    p = tmp_path / "out.h5"
    p.write_text("old")
    seen = []
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_path(p, suffix=".h5.part") as tmp:
            seen.append(tmp)
            assert tmp.parent == tmp_path and tmp.name.startswith(".out.h5.") and tmp.name.endswith(".h5.part")
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert p.read_text() == "old" and not seen[0].exists()
    assert [x.name for x in tmp_path.iterdir()] == ["out.h5"]
    with pytest.raises(KeyboardInterrupt):  # an interrupt too
        with atomic_path(p) as tmp:
            assert tmp.name.endswith(".part")
            raise KeyboardInterrupt
    assert [x.name for x in tmp_path.iterdir()] == ["out.h5"]
    with pytest.raises(RuntimeError):  # the temporary already gone: still the caller's error
        with atomic_path(p) as tmp:
            tmp.unlink()
            raise RuntimeError("gone")


def test_a_bare_list_of_box_objects_and_its_errors(tmp_path):
    p = tmp_path / "b.json"
    p.write_text('[{"box": [1, 2e-9, 3, 4e-9]}, {"box": [5, 1e-9, 6, 2e-9], "score": 0.5}]')
    assert read_boxes(p) == [[1, 2e-9, 3, 4e-9], [5, 1e-9, 6, 2e-9]]
    p.write_text('[[1, 2e-9, 3, 4e-9], {"box": [5, 1e-9, 6, 2e-9], "score": "x"}]')
    with pytest.raises(FormatError) as e:
        read_detections(p)
    assert str(e.value) == "b.json: target 1 has a bad score 'x'"  # one channel: no channel named
