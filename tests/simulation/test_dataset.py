"""gpr3d simulate: labelled samples, and a killed run that resumes with nothing lost or duplicated."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import gpr3d


def _hashes(folder: Path) -> dict:
    return {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in sorted(folder.iterdir())}


def _done(out: Path) -> list[Path]:
    d = out / "samples"
    return sorted(p for p in d.iterdir() if p.name.isdigit()) if d.exists() else []


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_killed_run_resumes_with_nothing_lost_or_duplicated(tmp_path):
    pytest.importorskip("gprMax")
    pytest.importorskip("distributed")
    out = tmp_path / "ds"
    n = 6
    cmd = [sys.executable, "-m", "gpr3d", "simulate", "--engine", "gprmax", "--preset", "tiny", "--n", str(n),
           "--workers", "1", "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 300
    while time.time() < deadline and len(_done(out)) < 2 and proc.poll() is None:
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGKILL)  # the job and its Dask workers, mid-sample
    proc.wait()
    before = {p.name: _hashes(p) for p in _done(out)}
    assert 2 <= len(before) < n, "the first run should have been cut short"
    assert not (out / "manifest.json").exists() or json.loads((out / "manifest.json").read_text())["n_samples"] < n

    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert f"{len(before)} already built" in r.stdout
    names = [p.name for p in (out / "samples").iterdir()]
    assert sorted(names) == [f"{i:06d}" for i in range(n)]  # all there, nothing half-built, no duplicates
    for name, h in before.items():  # finished samples were kept, not rebuilt
        assert _hashes(out / "samples" / name) == h
    manifest = json.loads((out / "manifest.json").read_text())
    assert [e["index"] for e in manifest["samples"]] == list(range(n))
    for e in manifest["samples"]:
        assert e["files"] == _hashes(out / "samples" / f"{e['index']:06d}")
    coco = json.loads((out / "coco.json").read_text())
    assert len(coco["images"]) == n and len(coco["annotations"]) >= n


def test_tiny_gprmax_sample_labels_sit_on_the_apex(tmp_path):
    pytest.importorskip("gprMax")
    from gpr3d.processing.picking import pick_peak
    from gpr3d.simulation.dataset import simulate_sample

    cfg = {"out": str(tmp_path), "seed": 0, "engine": "gprmax", "preset": "tiny", "image_height": 128}
    simulate_sample(cfg, 2)
    d = tmp_path / "samples" / "000002"
    s = gpr3d.read(d / "bscan.h5")
    assert s.metadata["simulation"]["gprmax_version"] == "4.0.1"
    assert json.loads((d / "scene.json").read_text())["name"] == s.metadata["scene"]["name"]
    labels = json.loads((d / "labels.json").read_text())["labels"]
    env = s.remove_background().envelope().data
    f = s.frequency_hz
    for lab in labels:
        t, _ = pick_peak(env, s.dt_s, int(round(lab["apex_trace"])), lab["apex_time_s"], 0.4 / f)
        assert abs(t - lab["apex_time_s"]) < 0.15 / f  # within 15 % of a period (FDTD grid delay included)
    from PIL import Image

    img = np.asarray(Image.open(d / "image.png"))
    assert img.shape == (128, s.n_traces, 3)


def test_forward_engine_dataset(tmp_path):
    pytest.importorskip("distributed")
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset

    summary = build_dataset(SimulateConfig(out=str(tmp_path), n=3, engine="forward", workers=1), progress=False,
                            log=lambda *_: None)
    assert summary["built"] == 3 and summary["in_manifest"] == 3
    again = build_dataset(SimulateConfig(out=str(tmp_path), n=3, engine="forward", workers=1), progress=False,
                          log=lambda *_: None)
    assert again["built"] == 0
    with pytest.raises(gpr3d.GPR3DError, match="other settings"):
        build_dataset(SimulateConfig(out=str(tmp_path), n=3, engine="forward", seed=9), progress=False,
                      log=lambda *_: None)


def test_pack_and_export_round_trip(tmp_path):
    pytest.importorskip("distributed")
    coco_mod = pytest.importorskip("pycocotools.coco")
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset
    from gpr3d.simulation.packed import PackedDataset, pack_dataset

    build_dataset(SimulateConfig(out=str(tmp_path / "ds"), n=3, engine="forward", workers=1), progress=False,
                  log=lambda *_: None)
    info = pack_dataset(tmp_path / "ds", tmp_path / "p.h5", regenerate="gpr3d simulate --engine forward --n 3")
    assert info["n"] == 3
    ds = PackedDataset(tmp_path / "p.h5")
    assert len(ds) == 3 and ds.regenerate.startswith("gpr3d simulate")
    for i in range(3):
        s, lab = ds[i]
        orig = gpr3d.read(tmp_path / "ds" / "samples" / f"{i:06d}" / "bscan.h5")
        # forward samples already have 512 samples: only float16 rounding separates them
        np.testing.assert_allclose(s.data, orig.data, atol=1e-3 * np.abs(orig.data).max())
        assert s.dt_s == pytest.approx(orig.dt_s, rel=1e-9, abs=0)
        assert lab == json.loads((tmp_path / "ds" / "samples" / f"{i:06d}" / "labels.json").read_text())
    coco = ds.export_coco(tmp_path / "coco", image_height=64)
    c = coco_mod.COCO(str(tmp_path / "coco" / "coco.json"))
    assert len(c.imgs) == 3 and len(c.anns) == len(coco["annotations"])
    assert (tmp_path / "coco" / c.imgs[1]["file_name"]).exists()
    # the command writes the same into a folder as a whole (manifest.json lists every image and coco.json)
    from gpr3d.cli.main import main
    from gpr3d.io.resultdir import check_result

    assert main(["dataset", "export", str(tmp_path / "p.h5"), str(tmp_path / "cli"), "--image-height", "64"]) == 0
    listed = set(check_result(tmp_path / "cli")["files"])
    assert listed == {"coco.json"} | {im["file_name"] for im in coco["images"]}
    assert json.loads((tmp_path / "cli" / "coco.json").read_text()) == coco


def test_records_of_different_lengths_pack_and_read_back(tmp_path):
    """Survey-scale records differ in trace count: packing pads them and reads each back at its own length."""
    pytest.importorskip("distributed")
    from gpr3d.io.packed import labelled_records
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset, write_manifest
    from gpr3d.simulation.packed import PackedDataset, pack_dataset

    build_dataset(SimulateConfig(out=str(tmp_path / "ds"), n=3, engine="forward", workers=1), progress=False,
                  log=lambda *_: None)
    p1 = tmp_path / "ds" / "samples" / "000001" / "bscan.h5"
    s1 = gpr3d.read(p1)
    short = s1.replace(data=s1.data[:17], positions_xyz=s1.positions_xyz[:17],
                       orientations_quat_wxyz=None if s1.orientations_quat_wxyz is None
                       else s1.orientations_quat_wxyz[:17])
    short.save(p1)
    write_manifest(tmp_path / "ds")
    pack_dataset(tmp_path / "ds", tmp_path / "p.h5")
    ds = PackedDataset(tmp_path / "p.h5")
    lengths = [gpr3d.read(tmp_path / "ds" / "samples" / f"{i:06d}" / "bscan.h5").n_traces for i in range(3)]
    assert lengths[1] == 17 and list(ds.n_traces) == lengths and ds.shape[1] == max(lengths)
    from_file = list(labelled_records(tmp_path / "p.h5"))
    from_dir = list(labelled_records(tmp_path / "ds"))
    assert [s.n_traces for s, _ in from_file] == [s.n_traces for s, _ in from_dir]
    assert from_file[1][0].n_traces == 17
    for (a, la), (b, lb) in zip(from_file, from_dir):
        np.testing.assert_allclose(a.data, b.data, atol=1e-3 * np.abs(b.data).max())
        assert la == lb
    assert [s.n_traces for s, _ in labelled_records(tmp_path / "ds", n=2, last=True)] == \
        [from_dir[1][0].n_traces, from_dir[2][0].n_traces]
    with pytest.raises(gpr3d.GPR3DError, match="not a gpr3d simulate dataset"):
        list(labelled_records(tmp_path))


def test_survey_preset_sample_runs_following_models_and_cleans_up(tmp_path, monkeypatch):
    """--preset survey: the sample is built from antenna-following models, its work folder removed when done."""
    pytest.importorskip("gprMax")
    import gpr3d.simulation.surveys as surveys
    from gpr3d.simulation.dataset import simulate_sample
    from gpr3d.simulation.scene import Antenna, Medium, Scene, Target

    def tiny(seed, index, host=None):
        s = Scene(medium=Medium("concrete", 6.0, 0.005), antenna=Antenna(2.0e9, 0.02), width_m=0.3, depth_m=0.08,
                  n_traces=4, trace_step_m=0.02, x_start_m=0.1, time_window_s=1.8e-9, seed=seed)
        s.targets = [Target("rebar", x_m=0.13, depth_m=0.03, radius_m=0.008)]
        return s

    monkeypatch.setattr(surveys, "sample_gprmax_survey_scene", tiny)
    cfg = {"out": str(tmp_path), "seed": 7, "engine": "gprmax", "preset": "survey", "image_height": 64}
    res = simulate_sample(cfg, 0)
    d = tmp_path / "samples" / "000000"
    assert not res["skipped"] and all((d / f).exists() for f in ("scene.json", "bscan.h5", "labels.json", "image.png"))
    assert not (tmp_path / "work" / "000000").exists()
    lab = json.loads((d / "labels.json").read_text())
    assert lab["simulation"]["runner"] == "following" and lab["n_traces"] == 4
    s = gpr3d.read(d / "bscan.h5")
    # the labelled apex lies on the record's trace nearest the rebar (x = 0.13 m: trace 1.5 at 0.1 + 0.02 i)
    assert lab["labels"][0]["apex_trace"] == pytest.approx((0.13 - s.positions_xyz[0, 0]) / 0.02, abs=0.2)
    assert simulate_sample(cfg, 0)["skipped"]  # a finished sample is not built again


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_start_index_and_time_limit_build_part_of_a_set_and_resume(tmp_path):
    """--start builds start..n-1 only (two machines can share one set); --max-seconds stops with every finished
    sample kept and the rest left for the next run; together they give the samples of one straight run."""
    pytest.importorskip("distributed")
    import json

    from gpr3d.simulation.dataset import SimulateConfig, build_dataset

    quiet = {"progress": False, "log": lambda *_: None}
    part = build_dataset(SimulateConfig(out=str(tmp_path / "a"), n=5, start=3, engine="forward", workers=1), **quiet)
    assert part["built"] == 2 and sorted(p.name for p in (tmp_path / "a" / "samples").iterdir()) == ["000003", "000004"]
    cut = build_dataset(SimulateConfig(out=str(tmp_path / "a"), n=5, engine="forward", workers=1, max_seconds=1e-3),
                        **quiet)
    assert cut["left"] >= 1 and cut["built"] + cut["left"] <= 3  # stopped before samples 0-2 all finished
    rest = build_dataset(SimulateConfig(out=str(tmp_path / "a"), n=5, engine="forward", workers=1), **quiet)
    assert rest["in_manifest"] == 5 and rest["built"] <= 3
    build_dataset(SimulateConfig(out=str(tmp_path / "b"), n=5, engine="forward", workers=1), **quiet)
    for i in range(5):  # the same labels as one uninterrupted run
        a = json.loads((tmp_path / "a" / "samples" / f"{i:06d}" / "labels.json").read_text())
        b = json.loads((tmp_path / "b" / "samples" / f"{i:06d}" / "labels.json").read_text())
        assert a["labels"] == b["labels"] and a["eps_r"] == b["eps_r"]
    for bad, msg in (({"start": 5}, "--start"), ({"start": -1}, "--start"), ({"max_seconds": 0.0}, "--max-seconds")):
        with pytest.raises(gpr3d.GPR3DError, match=msg):
            build_dataset(SimulateConfig(out=str(tmp_path / "c"), n=5, engine="forward", **bad), **quiet)
