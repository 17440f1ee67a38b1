"""references/detection/pseudo_labels.py: a box written as a YOLO line reads back as the same box in traces and
seconds (the inverse of read_yolo), under P-GPR's class of its kind."""

import numpy as np
import pytest

from tests.tools._script import load_script


@pytest.mark.parametrize("kind, name", [("rebar", "rebar"), ("steel_pipe", "rebar"), ("pvc_pipe", "pvc_pipe"),
                                        ("void", "pvc_pipe")])
def test_a_box_written_as_a_yolo_line_reads_back_the_same(tmp_path, kind, name):
    from PIL import Image

    from gpr3d.io.yolo import read_yolo

    mod = load_script("references/detection/pseudo_labels.py")
    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    Image.fromarray(np.random.default_rng(0).integers(0, 255, (256, 300), dtype=np.uint8)).save(
        tmp_path / "images" / "a.png")
    dt = 3.125e-11
    boxes = [[12.0, 40 * dt, 87.5, 130 * dt], [0.0, 0.0, 299.0, 255 * dt]]
    (tmp_path / "labels" / "a.txt").write_text("".join(mod.yolo_line(b, kind, 300, 256, dt) + "\n" for b in boxes))
    (survey, lab), = read_yolo(tmp_path, **mod.PGPR)
    assert (survey.n_traces, survey.n_samples) == (300, 256)
    for got, want in zip(lab["labels"], boxes):
        np.testing.assert_allclose(np.array(got["box"]) / [1, dt, 1, dt], np.array(want) / [1, dt, 1, dt], atol=1e-3)
        assert got["kind"] == name


def test_a_box_under_a_better_scored_box_is_dropped_as_an_echo():
    mod = load_script("references/detection/pseudo_labels.py")
    bar = {"box": [10.0, 1.0, 30.0, 3.0], "score": 0.9}  # height 2
    echo = {"box": [12.0, 2.0, 31.0, 4.0], "score": 0.8}  # its top 1 lower (> 0.3 x 2), its traces within
    beside = {"box": [40.0, 2.0, 60.0, 4.0], "score": 0.8}  # no shared traces
    shallow = {"box": [12.0, 1.5, 31.0, 4.0], "score": 0.8}  # top only 0.5 lower: 0.25 of the height
    deeper_bottom = {"box": [12.0, 2.0, 31.0, 2.9], "score": 0.8}  # its bottom above the bar's: not under it
    better = {"box": [12.0, 2.0, 31.0, 4.0], "score": 0.95}  # scored above the bar: kept, and the bar too
    half = {"box": [25.0, 2.0, 45.0, 4.0], "score": 0.8}  # shares 5 of 20 traces
    assert mod.drop_echoes([bar, echo, beside]) == [bar, beside]
    assert mod.drop_echoes([bar, shallow, deeper_bottom, half]) == [bar, shallow, deeper_bottom, half]
    assert mod.drop_echoes([bar, better]) == [bar, better]
    assert mod.under([0, 2, 10, 4], [5, 0, 15, 2]) and not mod.under([0, 2, 10, 4], [5, 0, 15, 2], overlap=0.6)


@pytest.mark.parametrize("args, line", [
    (["default", "--out", "{tmp}/o", "--score", "0"], "--score must lie in (0, 1], got 0.0"),
    (["default", "--out", "{tmp}/o", "--pgpr", "{tmp}"], "--pgpr {tmp} --split train: no train/images/ folder there"),
    (["{tmp}/none.pt", "--out", "{tmp}/o", "--pgpr", "{tmp}/p"], "no such weights file: {tmp}/none.pt"),
])
def test_wrong_arguments_are_one_line_before_any_work(tmp_path, args, line):
    import subprocess
    import sys

    from tests.tools._script import ROOT

    (tmp_path / "p" / "train" / "images").mkdir(parents=True)
    r = subprocess.run([sys.executable, str(ROOT / "references/detection/pseudo_labels.py"),
                        *(a.replace("{tmp}", str(tmp_path)) for a in args)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines()[-1].endswith("error: " + line.replace("{tmp}", str(tmp_path)))
    assert not (tmp_path / "o").exists()  # nothing made


def test_a_one_class_detectors_boxes_are_steel():
    mod = load_script("references/detection/pseudo_labels.py")
    assert mod.yolo_line([0, 0, 9, 1e-9], "hyperbola", 10, 100, 1e-10).split()[0] == "0"
    assert mod.yolo_line([0, 0, 9, 1e-9], "tank", 10, 100, 1e-10).split()[0] == "1"
