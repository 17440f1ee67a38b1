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


def test_several_gprmax_files_are_all_read_each_with_its_hold_out(tmp_path):
    """``--gprmax A:N B:M`` trains on both files' records, each less its last N / M, and names both in the weights."""
    from gpr3d.detection.refine import load_refiner
    from gpr3d.io.packed import PackedDataset

    a, b = REPO / "datasets" / "gprmax_survey_train.h5", REPO / "datasets" / "gprmax400.h5"
    na, nb = len(PackedDataset(a)), len(PackedDataset(b))
    out = tmp_path / "ref.pt"
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--pgpr", "none", "--gprmax",
                        f"{a}:{na - 3}", f"{b}:{nb - 2}", "--epochs", "1", "--per-label", "1"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    prov = load_refiner(out).provenance
    assert prov["data"] == (f"gprmax_survey_train.h5 (3 records, its last {na - 3} left out) + "
                            f"gprmax400.h5 (2 records, its last {nb - 2} left out)")
    assert "credit" not in prov  # no P-GPR label read


@pytest.mark.parametrize("spec, says", [("nowhere.h5", "no such file"), ("datasets/gprmax400.h5:x", "a whole number"),
                                        ("datasets/gprmax400.h5:-3", "a whole number")])
def test_a_wrong_gprmax_file_is_one_line_before_any_work(tmp_path, spec, says):
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "ref.pt"), "--pgpr", "none", "--gprmax",
                        str(REPO / spec)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert f"--gprmax {REPO / spec}" in last and says in last
    assert not (tmp_path / "ref.pt").exists()


def test_wall_scans_alone_train_a_refiner_that_read_no_real_label(tmp_path):
    """``--pgpr none --wall N``: the first N handheld wall scans of seed 1000 (their labels the boxes it learned),
    named in the weights, no P-GPR credit (the zero-shot line reads no real label)."""
    from gpr3d.detection.refine import load_refiner
    from gpr3d.simulation.surveys import survey_sample

    out = tmp_path / "ref.pt"
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--pgpr", "none", "--wall", "2",
                        "--epochs", "1", "--per-label", "1"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    n_labels = sum(len([x for x in survey_sample(1000, i, profile="wall")[1]["labels"] if x.get("visible", True)])
                   for i in range(2))
    assert f"over {n_labels} crops" in r.stdout  # one crop per label: the two wall scans' labels, no other record's
    prov = load_refiner(out).provenance
    assert prov["data"] == "survey_sample(1000, i < 2, profile='wall')"
    assert "credit" not in prov


def test_nothing_to_train_on_is_one_line(tmp_path):
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "ref.pt"), "--pgpr", "none"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "nothing to train on" in r.stderr.strip().splitlines()[-1]


def test_a_file_that_is_not_a_packed_dataset_is_one_line(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not hdf5 at all")
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "ref.pt"), "--pgpr", "none", "--gprmax",
                        str(bad)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith("train_refiner.py: ") and "bad.h5" in r.stderr
    assert not (tmp_path / "ref.pt").exists()


def test_rule_heads_give_p_gpr_pictures_their_own_head_and_quality_a_head_output(tmp_path):
    """``--rule-heads --quality N``: the weights name both rules and the quality head, the network has two heads of
    five outputs, and the P-GPR pictures teach the 'pgpr' head (training a head on them alone moves its boxes, not
    the other head's)."""
    import numpy as np

    from gpr3d.detection.refine import load_refiner

    pgpr = real_file("pgpr_1600MHz")
    a = REPO / "datasets" / "gprmax_survey_train.h5"
    from gpr3d.io.packed import PackedDataset

    out = tmp_path / "ref.pt"
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--pgpr", str(pgpr), "--only", "IECAS_00*",
                        "--gprmax", f"{a}:{len(PackedDataset(a)) - 2}", "--rule-heads", "--quality", "2",
                        "--quality-weights", "pgpr=0.5",
                        "--epochs", "1", "--per-label", "2"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    ref = load_refiner(out)
    assert ref.provenance["rules"] == ["gpr3d", "pgpr"] and ref.provenance["quality"] is True
    assert ref.provenance["quality_boxes"] == 2 and (ref.rules, ref.quality) == (("gpr3d", "pgpr"), True)
    assert ref.provenance["quality_weights"] == {"pgpr": 0.5}
    o = ref.predict_crops(np.random.default_rng(0).random((2, 3, 64, 64), dtype=np.float32))
    assert o.shape == (2, 10) and not np.allclose(o[:, :4], o[:, 5:9])


def test_a_fine_stage_of_p_gpr_s_rule_alone_averages_its_members(tmp_path):
    """``--rule-heads`` with P-GPR's pictures alone: one head, of the 'pgpr' rule; ``--members 2 --jitter-scale
    0.5``: two networks trained on boxes drawn half as far from the labels, in one file that averages their moves,
    and the file says so."""
    import numpy as np
    import torch

    from gpr3d.detection.refine import load_refiner

    pgpr = real_file("pgpr_1600MHz")
    out = tmp_path / "fine.pt"
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(out), "--pgpr", str(pgpr), "--only", "IECAS_002*",
                        "--rule-heads", "--members", "2", "--jitter-scale", "0.5", "--epochs", "1", "--per-label",
                        "2"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.count("member ") == 2
    ref = load_refiner(out)
    prov = ref.provenance
    assert prov["rules"] == ["pgpr"] and prov["members"] == 2 and prov["jitter_scale"] == 0.5
    assert ref.rules == ("pgpr",) and len(ref.net.members) == 2
    x = np.random.default_rng(0).random((3, 3, 64, 64), dtype=np.float32)
    with torch.inference_mode():
        each = [m(torch.from_numpy(x)).numpy() for m in ref.net.members]
    assert not np.allclose(each[0], each[1], atol=1e-3)  # two networks, not one twice
    np.testing.assert_allclose(ref.predict_crops(x), 0.5 * (each[0] + each[1]), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("args, says", [(["--pgpr", "none", "--synthetic", "2", "--members", "0"],
                                         "--members must be a whole number >= 1, got 0"),
                                        (["--pgpr", "none", "--wall", "-2"],
                                         "--synthetic and --wall are counts of records (whole numbers >= 0), got 0 "
                                         "and -2"),
                                        (["--pgpr", "none", "--synthetic", "2", "--jitter-scale", "0"],
                                         "--jitter-scale must be a number in (0, 4], got 0.0"),
                                        (["--pgpr", "none", "--synthetic", "2", "--jitter-scale", "nan"],
                                         "--jitter-scale must be a number in (0, 4], got nan"),
                                        (["--pgpr", "none", "--synthetic", "2", "--quality", "-1"],
                                         "--quality must be a whole number >= 0, got -1"),
                                        (["--pgpr", "none", "--synthetic", "2", "--quality", "2", "--quality-weights",
                                          "voc=1"], "--quality-weights voc=1: a rule (gpr3d, pgpr) = a number in 0..8"),
                                        (["--pgpr", "none", "--synthetic", "2", "--quality", "2", "--quality-weights",
                                          "pgpr=x"], "--quality-weights pgpr=x: a rule (gpr3d, pgpr) = a number"),
                                        (["--pgpr", "none", "--synthetic", "2", "--quality-weights", "pgpr=0"],
                                         "--quality-weights weigh a quality head: give --quality N too")])
def test_wrong_members_jitter_scale_and_quality_settings_are_one_line(tmp_path, args, says):
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "ref.pt"), *args],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert says in r.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "ref.pt").exists()
