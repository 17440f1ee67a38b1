"""references/detection/finetune_pgpr.py end to end on P-GPR's real pictures (skipped without them): the weights it
writes record how wide its training pictures' features are, which ``--trace-scales auto`` reads back."""

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("torch")

from tests.conftest import REPO, real_file  # noqa: E402


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_a_two_step_fine_tune_records_its_pictures_trace_width(tmp_path):
    from gpr3d.detection.infer import load_detector
    from gpr3d.detection.windows import WindowConfig, prepare, trace_width
    from gpr3d.io.yolo import read_yolo

    pgpr = real_file("pgpr_1600MHz")
    r = subprocess.run([sys.executable, str(REPO / "references" / "detection" / "finetune_pgpr.py"), "--out",
                        str(tmp_path / "ft"), "--pgpr", str(pgpr), "--only", "IECAS_00*", "--steps", "2", "--batch", "2",
                        "--seed", "3"],
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    det = load_detector(tmp_path / "ft" / "weights.pt", refiner="none")
    # the median over the very pictures it trained on, each read as the script reads them (the same numpy code on
    # the same host in both processes: equal to rounding, whatever the CPU)
    pictures = read_yolo(pgpr / "train", pattern="IECAS_00*", names=["steel", "pipe"], kinds="pipe=pvc_pipe",
                         pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9)
    assert len(pictures) >= 5
    want = float(np.median([trace_width(prepare(s, WindowConfig())) for s, _ in pictures]))
    assert det.provenance["trace_width"] == det.reference_width == pytest.approx(want, rel=1e-12)
    assert 8 < want < 14  # IECAS's features: about 11 traces wide (AIR's about 23)
    # --seed: the network's seed and the window draws' (1000 + it), as the provenance records them
    assert (det.provenance["config"]["seed"], det.provenance["config"]["data_seed"]) == (3, 1003)


def test_a_negative_seed_is_refused_in_one_line_before_any_work(tmp_path):
    r = subprocess.run([sys.executable, str(REPO / "references" / "detection" / "finetune_pgpr.py"), "--out",
                        str(tmp_path / "ft"), "--seed", "-2"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "--seed must be 0 or more, got -2" in r.stderr
    assert not (tmp_path / "ft").exists()


@pytest.mark.parametrize("extra, msg", [
    (["--wall-box-pad", "0.4"], "--wall-box-pad sets the wall scans' boxes: give --wall too"),
    (["--wall", "0.5", "--wall-box-pad", "2.5"], "--wall-box-pad must lie in 0..2 periods, got 2.5"),
    (["--wall-pad-wavelet"], "--wall-pad-wavelet sets the wall scans' boxes: give --wall too"),
])
def test_a_wrong_wall_box_pad_is_refused_in_one_line_before_any_work(tmp_path, extra, msg):
    r = subprocess.run([sys.executable, str(REPO / "references" / "detection" / "finetune_pgpr.py"), "--out",
                        str(tmp_path / "ft"), "--real", "0", *extra], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and msg in r.stderr, r.stderr
    assert not (tmp_path / "ft").exists()
