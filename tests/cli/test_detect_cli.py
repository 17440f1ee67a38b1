"""gpr3d detect / reconstruct --mask detect: the file contract, real recordings, and one-line errors."""

import json

import numpy as np
import pytest

import gpr3d

pytest.importorskip("torch")
pytest.importorskip("torchvision")

from tests.cli.test_cli import run_cli  # noqa: E402
from tests.conftest import real_file  # noqa: E402


def test_detect_on_the_real_dzt_writes_the_contract(tmp_path):
    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out, png = tmp_path / "det.json", tmp_path / "det.png"
    r = run_cli("--timings", tmp_path / "t.json", "detect", src, "--out", out, "--overlay", png)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    # where its time went: each stage once, in the order it ran (the detector's own inside 'detect')
    times = json.loads((tmp_path / "t.json").read_text())
    assert [k for k in times["stages"] if k not in ("compile", "other")] == [
        "load models", "read", "detect", "prepare", "windows", "network", "merge", "refine", "apexes", "depths", "write",
        "figures"]
    counts = {k: n for k, n in times["counts"].items() if k != "compile"}
    assert counts == {**dict.fromkeys(counts, 1), "load models": 2}  # the detector, then DepthNet
    assert times["stages"]["network"] <= d["wall_s"]  # the detector's own clock spans its stages
    inner = ("prepare", "windows", "network", "merge", "refine", "apexes")
    assert sum(times["stages"][k] for k in inner) <= d["wall_s"] + 1e-3
    assert d["refiner"] == "refiner_pgpr_synth_gprmax_whole_rules_quality"  # the shipped box refiner placed the shipped detector's boxes
    assert d["n_traces"] == 1040 and d["dt_s"] == pytest.approx(48e-9 / 512, rel=1e-9, abs=0)
    assert d["input"] == str(src)
    for t in d["targets"]:
        i0, t0, i1, t1 = t["box"]
        assert 0 <= i0 <= t["apex_trace"] <= i1 <= 1039
        assert 0 <= t0 <= t["apex_time_s"] <= t1 <= 511 * d["dt_s"]  # seconds from the first sample
        assert 0.5 <= t["score"] <= 1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"{len(d['targets'])} targets in 1040 traces" in r.stdout


@pytest.mark.parametrize("depth", ["none", "hybrid"])
def test_detect_on_the_embedded_dzt_imports_neither_scipy_signal_nor_ndimage(tmp_path, depth):
    # they cost ~1.3 s of start-up; the detector's path and the depth fits (gpr3d.inversion.hyperbola, the default
    # --depth hybrid: once 0.8 s of a 3.7 s detect here) use gpr3d.processing.analytic instead
    pytest.importorskip("onnxruntime")
    out = tmp_path / "d.json"
    code = ("import sys; from gpr3d.cli.main import main; "
            f"rc = main(['detect', 'src/gpr3d/data/FILE____032.DZT', '--depth', {depth!r}, '--out', {str(out)!r}]); "
            "print(rc, sorted(m for m in ('scipy.signal', 'scipy.ndimage', 'scipy.stats', 'torch') if m in sys.modules))")
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "0 []"
    d = json.loads(out.read_text())
    assert d["n_traces"] == 1040 and d["targets"] and all(t["score"] >= 0.5 for t in d["targets"])


@pytest.mark.parametrize("args, msg", [
    (["--score", "2"], "--score must lie in 0..1"),
    (["--weights", "{junk}"], "not a readable weights file"),
    (["--out", "{txt}"], "expected a .json file"),
    (["--trace-scales", "0.2"], "--trace-scales must be different factors in 0.25..4 or auto, separated by commas"),
    (["--trace-scales", "1,x"], "--trace-scales must be different factors in 0.25..4 or auto, separated by commas"),
    (["--trace-scales", "1,1"], "--trace-scales must be different factors in 0.25..4 or auto, separated by commas"),
    (["--trace-scales", "1,auto", "--weights", "{plain}"],
     "--trace-scales auto needs a detector that knows how wide its training"),
    (["--trace-scales", "nan"], "--trace-scales must be different factors in 0.25..4 or auto, separated by commas"),
    (["--refine-passes", "0"], "--refine-passes must be a whole number in 1..5, got 0"),
    (["--refine-passes", "6"], "--refine-passes must be a whole number in 1..5, got 6"),
    (["--refine-passes", "1", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--no-refine-mirror", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--box-rule", "pgpr", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--quality-weight", "0.5", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--duplicate-iou", "0.5", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--duplicate-iou", "none", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--duplicate-iou", "0"], "--duplicate-iou must be an overlap in (0, 1] or none, got '0'"),
    (["--duplicate-iou", "1.01"], "--duplicate-iou must be an overlap in (0, 1] or none, got '1.01'"),
    (["--duplicate-iou", "nan"], "--duplicate-iou must be an overlap in (0, 1] or none, got 'nan'"),
    (["--duplicate-iou", "half"], "--duplicate-iou must be an overlap in (0, 1] or none, got 'half'"),
    (["--fine-refiner", "none", "--refiner", "none"], "say how the box refiner is applied: not with --refiner none"),
    (["--fine-refiner", "{missing}"], "--fine-refiner {missing}: no such file"),
    (["--fine-refiner", "{junk}"], "junk.pt: not a readable"),
    (["--quality-weight", "-1"], "--quality-weight must be a number in 0..8, got -1.0"),
    (["--quality-weight", "nan"], "--quality-weight must be a number in 0..8, got nan"),
])
def test_detect_bad_arguments_one_line(tmp_path, args, msg):
    from gpr3d.core.survey import Survey

    src = tmp_path / "s.h5"
    Survey(data=np.random.default_rng(0).normal(size=(50, 128)).astype(np.float32), dt_s=1e-10).save(src)
    (tmp_path / "junk.pt").write_bytes(b"junk")
    if "{plain}" in args:  # the shipped weights less the width of their training pictures (fine-tunes record it)
        import torch

        from gpr3d.detection.weights import DEFAULT_WEIGHTS

        obj = torch.load(DEFAULT_WEIGHTS, weights_only=True)
        obj["provenance"].pop("trace_width", None)
        torch.save(obj, tmp_path / "plain.pt")
    names = {"junk": tmp_path / "junk.pt", "txt": tmp_path / "x.txt", "plain": tmp_path / "plain.pt",
             "missing": tmp_path / "nope.pt"}
    args, msg = [a.format(**names) for a in args], msg.format(**names)
    base = ["detect", src, "--out", tmp_path / "d.json"]
    if "--out" in args:
        base = ["detect", src]
    r = run_cli(*base, *args)
    assert r.returncode == 1
    assert msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_detect_with_views_gives_what_the_library_gives(tmp_path):
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.registry import read

    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out = tmp_path / "det.json"
    r = run_cli("detect", src, "--out", out, "--depth", "none", "--mirror", "--trace-scales", "1,2")
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    det = load_detector()
    det.trace_scales, det.mirror = (1.0, 2.0), True
    want = det.detect(read(src), score_threshold=0.5)
    one = load_detector().detect(read(src), score_threshold=0.5)
    # each view twice (mirrored): 1040 traces in 8 windows of 256 (half overlapping), x2 2079 traces in 16
    assert one["n_windows"] == 8 and d["n_windows"] == want["n_windows"] == 2 * 8 + 2 * 16
    assert d["views"] == {"trace_scales": [1.0, 2.0], "mirror": True}
    assert one["views"] == {"trace_scales": [1.0], "mirror": False}
    got = np.array([t["box"] for t in d["targets"]])
    assert got.shape == (len(want["targets"]), 4)
    # the command and this process may run the network on other thread counts (float32 sums in another order):
    # boxes equal to a few parts in a million, far inside what the views move them by (below)
    assert np.allclose(got, [t["box"] for t in want["targets"]], rtol=1e-5, atol=0)
    # the views moved the boxes: not what the record alone gives
    plain = np.array([t["box"] for t in one["targets"]])
    assert got.shape != plain.shape or not np.allclose(got, plain, rtol=1e-3, atol=0)


def test_eval_detector_on_a_dataset_folder_matches_the_library(tmp_path):
    """`gpr3d eval detector --data` reports what evaluate_detector finds on the same records."""
    pytest.importorskip("distributed")
    pytest.importorskip("pycocotools")
    from gpr3d.detection.evaluate import evaluate_detector
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.packed import labelled_records
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset
    from gpr3d.simulation.surveys import survey_sample

    ds = tmp_path / "ds"
    build_dataset(SimulateConfig(out=str(ds), n=2, engine="forward", workers=1), progress=False, log=lambda *_: None)
    # put a survey-scale record in place of sample 1 (its own labels), so the set is not trivially empty
    s, lab = survey_sample(777, 3)
    s.save(ds / "samples" / "000001" / "bscan.h5")
    (ds / "samples" / "000001" / "labels.json").write_text(json.dumps(lab))
    r = run_cli("eval", "detector", "--data", ds)
    assert r.returncode == 0, r.stderr
    m = evaluate_detector(load_detector(), labelled_records(ds), score_threshold=0.5)  # as the command loads it
    assert f"{m['n_records']} records, {m['n_true']} targets" in r.stdout
    lines = r.stdout.strip().splitlines()
    row = lines[lines.index("|---|---|---|---|---|---|---|") + 1].split("|")
    assert float(row[1]) == pytest.approx(m["mAP@0.75"], abs=6e-4)
    assert float(row[4]) == pytest.approx(m["AR@100"], abs=6e-4)
    assert m["n_true"] >= 3 and m["n_records"] == 2
    by_kind = m["apex_recall_by_kind"]
    assert sum(v["n"] for v in by_kind.values()) == m["n_true"]
    assert sum(v["found"] for v in by_kind.values()) == round(m["apex_recall"] * m["n_true"])
    assert lines[-1].startswith("apex recall by kind: ")


@pytest.mark.parametrize("args, msg", [
    (["--data", "{missing}"], "no such file or folder"),
    (["--data", "{junk}"], "corrupt or truncated"),
    (["--n", "0"], "--n must be at least 1"),
])
def test_eval_detector_bad_arguments_one_line(tmp_path, args, msg):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"nothing here")
    args = [a.format(missing=tmp_path / "nope.h5", junk=junk) for a in args]
    r = run_cli("eval", "detector", *args)
    assert r.returncode != 0
    assert msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_detect_with_depths_on_one_file_of_every_real_folder(tmp_path):
    """Every radar's first file, as a user first tries it: the detector, DepthNet's host permittivity and the depths
    of what it found. MALA's ten_col.rd3 stood still for seven of its ten traces (a few GPS fixes): its depth stage
    once asked for 59 GiB."""
    from tests.conftest import real_files

    files = {}
    for f in real_files():
        files.setdefault(f.parent, f)
    if not files:
        pytest.skip("real data not available")
    for src in files.values():
        out = tmp_path / f"{src.stem}.json"
        r = run_cli("detect", src, "--out", out)
        assert r.returncode == 0, f"{src}: {r.stderr}"
        d = json.loads(out.read_text())
        n = gpr3d.read(src).n_traces
        assert d["n_traces"] == n and f"targets in {n} traces" in r.stdout, src
        eps = d["permittivity"]["eps_r"] if d.get("permittivity") else None
        # a record with positions (or a DZT's marks) has its host permittivity; one without says why not
        assert (eps is not None and 1 <= eps <= 81) or "no trace positions" in r.stderr, (src, d.get("permittivity"), r.stderr)


@pytest.mark.parametrize("given, want", [("none", None), ("0.7", 0.7), ("NONE", None), ("1", 1.0)])
def test_detect_lowers_duplicates_as_told_and_says_so(tmp_path, given, want):
    """``--duplicate-iou``: the scores the library gives with that overlap (or none), and the JSON says which."""
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.registry import read

    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out = tmp_path / "det.json"
    r = run_cli("detect", src, "--out", out, "--depth", "none", "--score", "0.05", "--duplicate-iou", given)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert d["refine"]["duplicate_iou"] == want
    det = load_detector()
    det.duplicate_iou = want
    lib = det.detect(read(src), score_threshold=0.05)
    assert [t["score"] for t in d["targets"]] == pytest.approx([t["score"] for t in lib["targets"]], rel=1e-6)


def test_detect_applies_the_refiner_as_told_and_says_so(tmp_path):
    """``--refine-passes 1 --no-refine-mirror``: the boxes the library gives with one look at each box, not the
    default two mirrored passes; the JSON says which."""
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.registry import read

    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out = tmp_path / "det.json"
    r = run_cli("detect", src, "--out", out, "--depth", "none", "--refine-passes", "1", "--no-refine-mirror")
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    # (the shipped refiner: gpr3d's head for a recording; a real radar's file: its quality not weighing the scores)
    assert d["refine"] == {"mirror": False, "passes": 1, "fine": None, "duplicate_iou": 0.5, "rule": "gpr3d",
                           "quality_weight": 0.0}
    want = load_detector(refine_mirror=False, refine_passes=1).detect(read(src), score_threshold=0.5)
    default = load_detector().detect(read(src), score_threshold=0.5)
    assert default["refine"] == {"mirror": True, "passes": 2, "fine": None, "duplicate_iou": 0.5, "rule": "gpr3d",
                                 "quality_weight": 0.0}
    assert default["targets"]  # (weighed by the quality, the quick start's processed copy kept none at 0.5)
    got = np.array([t["box"] for t in d["targets"]])
    assert got.shape == (len(want["targets"]), 4)
    assert np.allclose(got, [t["box"] for t in want["targets"]], rtol=1e-5, atol=0)
    two = np.array([t["box"] for t in default["targets"]])
    assert got.shape != two.shape or not np.allclose(got, two, rtol=1e-3, atol=0)
