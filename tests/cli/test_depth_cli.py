"""gpr3d depth / detect depths / eval depth / train depthnet: values against known truth, one-line errors."""

import json

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("torchvision")

from tests.cli.test_cli import run_cli  # noqa: E402
from tests.conftest import real_file  # noqa: E402
from tests.inversion.test_depthnet import hyperbola_record  # noqa: E402


@pytest.fixture(scope="module")
def diffractor(tmp_path_factory):
    d = tmp_path_factory.mktemp("depth")
    s, lab = hyperbola_record(spacing=0.01, eps=9.0, depth=0.3, x0=1.0, length=2.0)
    s.save(d / "line.h5")
    (d / "boxes.json").write_text(json.dumps({"targets": lab["labels"]}))
    return d, lab


def test_depth_table_with_the_fit_gives_the_diffractor_back(diffractor, tmp_path):
    d, lab = diffractor
    out = tmp_path / "dep.json"
    r = run_cli("depth", d / "line.h5", "--boxes", d / "boxes.json", "--method", "fit", "--out", out)
    assert r.returncode == 0, r.stderr
    head = r.stdout.splitlines()[0]
    eps = float(head.split("host eps_r ")[1].split()[0])
    assert eps == pytest.approx(9.0, rel=0.02)
    row = [x for x in r.stdout.splitlines() if x.startswith("| 0 |")][0].split("|")
    assert float(row[3]) == pytest.approx(1.0, abs=0.001)  # x along the profile
    assert float(row[5]) == pytest.approx(0.3, abs=0.005)  # depth to top
    res = json.loads(out.read_text())
    assert res["permittivity"]["method"] == "fit"
    assert res["targets"][0]["depth_m"] == pytest.approx(0.3, abs=0.005)


def test_depth_checks_the_boxes_it_is_given(diffractor, tmp_path):
    d, lab = diffractor
    (tmp_path / "bad.json").write_text("[1, 2]")
    r = run_cli("depth", d / "line.h5", "--boxes", tmp_path / "bad.json", "--method", "fit")
    assert r.returncode == 1 and "box 0 must be 4 numbers" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    # a junk apex is dropped (the box's own is used); a box past the record's end is cut to it
    box = list(lab["labels"][0]["box"])
    box[2] += 5000
    (tmp_path / "odd.json").write_text(json.dumps([{"box": box, "apex_trace": "x", "apex_time_s": None}]))
    out = tmp_path / "o.json"
    r = run_cli("depth", d / "line.h5", "--boxes", tmp_path / "odd.json", "--method", "fit", "--out", out)
    assert r.returncode == 0, r.stderr
    t = json.loads(out.read_text())["targets"][0]
    assert t["box"][2] == 200.0 and "apex_trace" not in t


def test_depth_without_positions_needs_a_spacing(diffractor, tmp_path):
    from gpr3d.core.survey import Survey

    d, lab = diffractor
    s = Survey.load(d / "line.h5").replace(positions_xyz=None)
    s.save(tmp_path / "bare.h5")
    r = run_cli("depth", tmp_path / "bare.h5", "--boxes", d / "boxes.json", "--method", "fit")
    assert r.returncode == 1 and "--trace-spacing" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = run_cli("depth", tmp_path / "bare.h5", "--boxes", d / "boxes.json", "--method", "fit", "--trace-spacing", "0.01")
    assert r.returncode == 0, r.stderr
    assert float(r.stdout.split("host eps_r ")[1].split()[0]) == pytest.approx(9.0, rel=0.02)
    r = run_cli("depth", tmp_path / "bare.h5", "--trace-spacing", "-1")
    assert r.returncode == 1 and "--trace-spacing must be a positive" in r.stderr


def test_detect_on_the_real_dzt_adds_permittivity_depths_and_positions(tmp_path):
    import gpr3d

    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out = tmp_path / "det.json"
    r = run_cli("detect", src, "--out", out)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    p = d["permittivity"]
    assert p["method"] == "hybrid" and 1.0 <= p["eps_r"] <= 81.0 and p["sigma_eps_r"] > 0
    assert "net" in p and f"host eps_r {p['eps_r']:.2f}" in r.stdout
    s = gpr3d.read(src)
    for t in d["targets"]:
        assert t["x_m"] == pytest.approx(float(np.interp(t["apex_trace"], np.arange(s.n_traces), s.distances_m)),
                                         abs=1e-9)
        if t["depth_m"] is not None:  # two-way time to depth with the host speed: never deeper than the window
            assert 0 < t["depth_m"] < 0.5 * 299792458 / p["eps_r"] ** 0.5 * s.time_window_s
    r = run_cli("detect", src, "--out", out, "--depth", "none")
    assert r.returncode == 0 and "permittivity" not in json.loads(out.read_text())


def test_eval_depth_matches_the_library(tmp_path):
    pytest.importorskip("distributed")
    from gpr3d.inversion.depthnet import DepthEstimator
    from gpr3d.inversion.evaluate import depth_rows, depth_table
    from gpr3d.io.packed import labelled_records
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset
    from gpr3d.simulation.surveys import survey_sample

    ds = tmp_path / "ds"
    build_dataset(SimulateConfig(out=str(ds), n=1, engine="forward", workers=1), progress=False, log=lambda *_: None)
    s, lab = survey_sample(777, 5)
    s.save(ds / "samples" / "000000" / "bscan.h5")
    (ds / "samples" / "000000" / "labels.json").write_text(json.dumps(lab))
    r = run_cli("eval", "depth", "--data", ds)
    assert r.returncode == 0, r.stderr
    table = depth_table(depth_rows(labelled_records(ds), estimator=DepthEstimator.load()))
    assert table[2] in r.stdout and table[-1] in r.stdout
    assert any(line.startswith("| net | all |") for line in table)


@pytest.mark.parametrize("args, msg", [
    (["--records", "0"], "--records must be at least 1"),
    (["--packed", "{missing}"], "missing.h5"),
    (["--optimiser", "lbfgs"], "unknown optimiser 'lbfgs'"),
    (["--batch", "1"], "--batch must be an integer >= 2"),
    (["--arch", "vgg16"], "unknown DepthNet encoder 'vgg16'"),
    (["--init", "default"], "ships DepthNet as ONNX"),
    (["--init", "{missing}"], "no such DepthNet weights file"),
])
def test_train_depthnet_bad_arguments_one_line(tmp_path, args, msg):
    args = [a.format(missing=tmp_path / ("missing.pt" if "--init" in args else "missing.h5")) for a in args]
    r = run_cli("train", "depthnet", "--out", tmp_path / "run", *args)
    assert r.returncode == 1 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_depth_with_a_known_radius_reads_the_rod_where_the_point_reads_it_low(tmp_path):
    from tests.inversion.test_hyperbola import _rods_record

    s, boxes, apexes, targets, eps = _rods_record()
    s.save(tmp_path / "rods.h5")
    x0, top, r = targets[2]  # the rod of 5 cm radius, top 25 cm deep
    (tmp_path / "b.json").write_text(json.dumps({"targets": [{"box": boxes[2], "apex_trace": apexes[2][0],
                                                              "apex_time_s": apexes[2][1]}]}))
    out = tmp_path / "d.json"
    got = {}
    for extra in ([], ["--radius", "0.05"]):
        res = run_cli("depth", tmp_path / "rods.h5", "--boxes", tmp_path / "b.json", "--method", "fit", "--out", out,
                      *extra)
        assert res.returncode == 0, res.stderr
        got[bool(extra)] = json.loads(out.read_text())
    known, point = got[True], got[False]
    assert known["permittivity"]["fit"]["model"] == "cylinder, radius given"
    assert known["permittivity"]["eps_r"] == pytest.approx(eps, rel=0.02)
    assert known["targets"][0]["depth_m"] == pytest.approx(top, abs=0.005)
    assert point["permittivity"]["fit"]["model"] == "point"
    assert point["permittivity"]["eps_r"] < eps * (1 - 0.5 * r / (top + r))


@pytest.mark.parametrize("args, msg", [
    (["depth", "{rec}", "--radius", "-0.01", "--method", "fit"], "--radius must be a radius in metres in 0..50, got -0.01"),
    (["depth", "{rec}", "--radius", "nan", "--method", "fit"], "--radius must be a radius in metres in 0..50, got nan"),
    (["depth", "{rec}", "--radius", "0.01", "--method", "net"],
     "--radius is used by the hyperbola fit: give it with fit or hybrid, not net"),
    (["detect", "{rec}", "--out", "{tmp}/d.json", "--radius", "0.01", "--depth", "none"],
     "--radius is used by the hyperbola fit: give it with fit or hybrid, not none"),
    (["reconstruct", "{rec}", "--out", "{tmp}/r", "--radius", "0.01", "--eps-r", "6"],
     "--radius is used to estimate eps_r: leave --eps-r out, or leave --radius out"),
])
def test_a_wrong_radius_is_one_line_before_any_work(diffractor, tmp_path, args, msg):
    d, _ = diffractor
    r = run_cli(*[a.format(rec=d / "line.h5", tmp=tmp_path) for a in args])
    assert r.returncode == 1 and r.stderr.strip() == f"gpr3d: error: {msg}", r.stderr
    assert not (tmp_path / "d.json").exists() and not (tmp_path / "r").exists()
