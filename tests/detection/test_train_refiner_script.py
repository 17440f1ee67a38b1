"""references/detection/train_refiner.py on P-GPR's real pictures (skipped without them): ``--only`` trains on one
radar's pictures (the device-held-out refiner) and says so in the weights; a glob that matches none is one line."""

import subprocess
import sys

import pytest

pytest.importorskip("torch")

from tests.conftest import REPO, real_file  # noqa: E402

SCRIPT = REPO / "references" / "detection" / "train_refiner.py"


def test_only_trains_on_the_pictures_it_names_and_records_them(tmp_path):
    from gpr3d.detection.refine import load_refiner
    from gpr3d.io.yolo import read_yolo

    pgpr = real_file("pgpr_1600MHz")
    out = tmp_path / "ref.pt"
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--pgpr", str(pgpr), "--only", "IECAS_00*",
                        "--epochs", "1", "--per-label", "1"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    n = len(read_yolo(pgpr / "train", pattern="IECAS_00*", names=["steel", "pipe"], kinds="pipe=pvc_pipe",
                      pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9))
    n_all = len(list((pgpr / "train" / "images").glob("*.png")))
    assert 0 < n < n_all
    prov = load_refiner(out).provenance
    assert prov["data"] == f"P-GPR train IECAS_00* ({n} B-scans)"
    assert "--only IECAS_00*" in prov["command"] and "CC BY 4.0" in prov["credit"]


def test_only_matching_no_picture_is_one_line_naming_it(tmp_path):
    pgpr = real_file("pgpr_1600MHz")
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "ref.pt"), "--pgpr", str(pgpr), "--only",
                        "NOPE_*"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    assert "--only 'NOPE_*': no P-GPR train picture matches" in r.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "ref.pt").exists()
