"""Labelled pictures on the command line: `gpr3d detect` on a PNG with its time axis, `gpr3d eval detector --labels`
on a YOLO dataset (the library's numbers), and every wrong label argument in one line before any work."""

import json

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("torch")
pytest.importorskip("torchvision")

from tests.cli.test_cli import run_cli  # noqa: E402

PM = "s_per_px=3.125e-11"


def _yolo(root):
    """Two 300 x 64 pictures with one labelled hyperbola each (a bright arc drawn on noise)."""
    rng = np.random.default_rng(0)
    for k, cx in enumerate((100, 180)):
        img = 128 + 10 * rng.normal(size=(64, 300))
        x = np.arange(300)
        t = np.sqrt(20.0**2 + ((x - cx) * 0.4) ** 2)  # rows of a hyperbola with its apex at row 20
        for dy in range(3):
            img[np.clip((t + dy).astype(int), 0, 63), x] = 250 - 80 * dy
        (root / "images").mkdir(parents=True, exist_ok=True)
        (root / "labels").mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(root / "images" / f"b{k}.png")
        (root / "labels" / f"b{k}.txt").write_text(f"{k} {cx / 300:.6f} 0.5 0.4 0.7\n")
    return root


def test_detect_takes_a_picture_with_its_time_axis(tmp_path):
    root = _yolo(tmp_path / "ds")
    out = tmp_path / "d.json"
    r = run_cli("detect", root / "images" / "b0.png", "--pixel-map", PM, "--frequency", "1.6e9", "--out", out)
    assert r.returncode == 0, r.stderr
    from gpr3d.detection.infer import load_detector

    kinds = load_detector().kinds
    d = json.loads(out.read_text())
    assert (d["n_traces"], d["dt_s"]) == (300, 3.125e-11)
    for t in d["targets"]:
        if kinds:  # the kind it names, with its share of the score: at least an even one
            assert t["kind"] in kinds and 1 / len(kinds) - 1e-6 <= t["kind_score"] <= 1
            # every kind's share, the best of them the kind named (rounded to 4 places)
            sh = t["kind_shares"]
            assert list(sh) == kinds and abs(sum(sh.values()) - 1) < 1e-3 and max(sh, key=sh.get) == t["kind"]
            assert sh[t["kind"]] == pytest.approx(t["kind_score"], abs=1e-4)
        else:  # a one-class model names no kind
            assert t["kind"] == "target" and t["kind_score"] is None and "kind_shares" not in t
        assert 0 <= t["box"][0] <= t["box"][2] <= 299 and 0 <= t["box"][1] <= t["box"][3] <= 63 * 3.125e-11


def test_eval_detector_on_a_yolo_dataset_matches_the_library(tmp_path):
    pytest.importorskip("pycocotools")
    from gpr3d.detection.evaluate import evaluate_detector
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.yolo import read_yolo

    root = _yolo(tmp_path / "ds")
    r = run_cli("eval", "detector", "--labels", root, "--pixel-map", PM, "--class-names", "steel,pipe",
                "--class-kinds", "pipe=pvc_pipe", "--labels-frequency", "1.6e9")
    assert r.returncode == 0, r.stderr
    m = evaluate_detector(load_detector(), read_yolo(root, names=["steel", "pipe"], kinds="pipe=pvc_pipe",
                                                     pixel_map=PM, frequency_hz=1.6e9))
    lines = r.stdout.strip().splitlines()
    assert lines[0] == f"{root} (2 labelled B-scans): 2 records, 2 targets"
    row = lines[lines.index("|---|---|---|---|---|---|---|") + 1].split("|")
    assert float(row[2]) == pytest.approx(m["mAP@0.5"], abs=6e-4)
    assert f"class-agnostic: mAP@[.5:.95] {m['mAP']:.3f}, recall@0.5 {m['recall@0.5']:.3f}" in lines
    assert lines[-1] == "apex recall by kind: " + ", ".join(
        f"{k} {v['recall']:.2f} ({v['found']}/{v['n']})" for k, v in m["apex_recall_by_kind"].items())
    assert set(m["apex_recall_by_kind"]) == {"rebar", "pvc_pipe"}


@pytest.mark.parametrize("args, msg", [
    (["detect", "{png}", "--out", "{d}/x.json"], "b0.png is a picture: give its time axis (--pixel-map s_per_px=SECONDS)"),
    (["detect", "{png}", "--out", "{d}/x.json", "--pixel-map", "s_per_px=5"],
     "pixel map s_per_px = 5.0 s is not a plausible row interval"),
    (["detect", "{png}", "--out", "{d}/x.json", "--pixel-map", PM, "--frequency", "16"],
     "frequency 16.0 Hz is not a GPR antenna's (1 MHz .. 100 GHz; give Hz, e.g. 1.6e9)"),
    (["detect", "{h5}", "--out", "{d}/x.json", "--pixel-map", PM],
     "--pixel-map is for pictures (PNG, JPG, ...); {h5} is a radar file"),
    (["eval", "detector", "--labels", "{ds}"], "YOLO pictures carry no time axis"),
    (["eval", "detector", "--labels", "{ds}", "--pixel-map", PM, "--class-kinds", "pipe=tube"],
     "kinds: pipe=tube: 'tube' is not a target kind"),
    (["eval", "detector", "--labels", "{ds}", "--pixel-map", PM, "--class-names", "a,,b"],
     "a list of names must be comma-separated words, got 'a,,b'"),
    (["eval", "detector", "--labels", "{ds}", "--data", "{h5}", "--pixel-map", PM], "give --data or --labels, not both"),
    (["eval", "detector", "--labels", "{ds}", "--pixel-map", PM, "--class-names", "a"],
     "b1.txt: line 1: class 1 is not a class id (classes 0..0)"),
    (["train", "detector", "--out", "{d}/t", "--kinds", "rebar,tube"], "--kinds must name distinct target kinds"),
    (["train", "detector", "--out", "{d}/t", "--kinds", "rebar,rebar"], "--kinds must name distinct target kinds"),
    (["train", "detector", "--out", "{d}/t", "--freeze", "7"], "--freeze must be an integer in 0..4"),
    (["train", "depthnet", "--out", "{d}/t", "--augment"],
     "--augment is for the detector; DepthNet trains on its records as they are"),
    (["train", "depthnet", "--out", "{d}/t", "--wall-fraction", "0.5"],
     "--wall-fraction is for the detector; DepthNet trains on its records as they are"),
    (["train", "detector", "--out", "{d}/t", "--wall-fraction", "1.5"], "--wall-fraction must lie in 0..1, got 1.5"),
    (["train", "detector", "--out", "{d}/t", "--labels", "{ds}", "--pixel-map", PM, "--labels-frequency", "-3"],
     "frequency -3.0 Hz is not a GPR antenna's"),
])
def test_wrong_label_arguments_get_one_line(tmp_path, args, msg):
    from gpr3d.core.survey import Survey

    root = _yolo(tmp_path / "ds")
    h5 = tmp_path / "s.h5"
    Survey(data=np.zeros((20, 64), np.float32), dt_s=1e-10).save(h5)
    fill = dict(png=root / "images" / "b0.png", d=tmp_path, ds=root, h5=h5)
    r = run_cli(*[a.format(**fill) for a in args])
    assert r.returncode == 1, r.stdout
    assert msg.format(**fill) in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "x.json").exists() and not (tmp_path / "t").exists()


def test_detect_on_a_real_picture_moves_its_boxes_once_more_by_the_fine_stage_unless_told(tmp_path):
    """The shipped P-GPR validation picture: by default the refiner's fine stage (P-GPR's rule) moves each box once
    more after the refiner's passes, and the JSON names it; ``--fine-refiner none`` leaves the passes' boxes. Each
    is the library's detection of the same picture."""
    from importlib.resources import files

    from gpr3d.detection.infer import load_detector
    from gpr3d.io.userlabels import read_picture

    png = files("gpr3d") / "data" / "pgpr" / "images" / "IECAS_0032.png"
    survey = read_picture(png, PM, frequency_hz=1.6e9)
    got = {}
    for fine in ("auto", "none"):
        out = tmp_path / f"{fine}.json"
        r = run_cli("detect", png, "--pixel-map", PM, "--frequency", "1.6e9", "--depth", "none", "--fine-refiner", fine,
                    "--out", out)
        assert r.returncode == 0, r.stderr
        got[fine] = json.loads(out.read_text())
        lib = load_detector(fine_refiner=fine).detect(survey, score_threshold=0.5)
        assert got[fine]["refine"] == lib["refine"]
        assert np.allclose([t["box"] for t in got[fine]["targets"]], [t["box"] for t in lib["targets"]], rtol=1e-6)
    assert got["auto"]["refine"]["fine"] == "refiner_fine_pgpr_5" and got["none"]["refine"]["fine"] is None
    assert got["auto"]["refine"]["rule"] == got["none"]["refine"]["rule"] == "pgpr"
    a = np.array([t["box"] for t in got["auto"]["targets"]])
    b = np.array([t["box"] for t in got["none"]["targets"]])
    assert len(a) == len(b) >= 5 and not np.allclose(a, b)  # the same boxes, moved
