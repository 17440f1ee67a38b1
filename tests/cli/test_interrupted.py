"""Long commands killed at seeded random moments (issue 31): a folder holds the previous complete result or the new
complete result, never a mix, and a re-run of the same line gives what an uninterrupted run gives."""

import json
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from gpr3d.io.resultdir import check_result, open_result
from tests.conftest import pipe_walk_files


@pytest.fixture(scope="module")
def line(tmp_path_factory):
    return pipe_walk_files(tmp_path_factory.mktemp("kill"), 900)


def _cmd(d, out, eps):
    return [sys.executable, "-m", "gpr3d", "reconstruct", str(d / "line.h5"), "--poses", str(d / "walk.tum"),
            "--out", str(out), "--max-depth", "0.6", "--eps-r", str(eps)]


def _eps_of_result(out) -> float:
    """eps_r of the result in ``out``, after checking that every file belongs to that one run."""
    check_result(out)
    cfg = json.loads((out / "config.json").read_text())["eps_r"]
    with h5py.File(out / "volume.h5") as f:
        vol = float(f.attrs["eps_r"])
    assert cfg == vol, (cfg, vol)  # the volume and the config of one run
    return cfg


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_reconstruct_killed_at_random_moments_leaves_one_whole_result(line, tmp_path):
    out, fresh = tmp_path / "r", tmp_path / "fresh"
    r = subprocess.run(_cmd(line, fresh, 9), capture_output=True, text=True, timeout=900)  # the uninterrupted run
    assert r.returncode == 0, r.stderr
    t0 = time.perf_counter()  # the second run, its kernels compiled: the span the kills are drawn in
    r = subprocess.run(_cmd(line, out, 6), capture_output=True, text=True, timeout=900)
    full = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    assert _eps_of_result(out) == 6.0
    rng = np.random.default_rng(31)
    seen, before = [], 6.0
    for eps in (7.0, 8.0, 9.0):  # each run asks for another eps_r: what is left tells which run's result it is
        at = float(rng.uniform(0.2, 1.05)) * full
        p = subprocess.Popen(_cmd(line, out, eps), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(at)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        open_result(out)  # what the next run (or a reader) does first
        left = _eps_of_result(out)
        assert left in (before, eps), (at, before, eps, left)
        seen.append((round(at, 1), eps, left))
        before = left
        assert sorted(q.name for q in out.iterdir() if q.name.startswith(".")) == []
    # the same line to the end: the result an uninterrupted run gives
    r = subprocess.run(_cmd(line, out, 9), capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    assert _eps_of_result(out) == 9.0
    with h5py.File(out / "volume.h5") as a, h5py.File(fresh / "volume.h5") as b:
        np.testing.assert_allclose(a["envelope"][()], b["envelope"][()], rtol=1e-6, atol=1e-6 * np.abs(b["envelope"][()]).max())
    assert json.loads((out / "targets.json").read_text()) == json.loads((fresh / "targets.json").read_text())
    print("kills (s after the start, eps_r asked, eps_r left):", seen, f"full run {full:.1f} s")


def _train_cmd(out):
    return [sys.executable, "-m", "gpr3d", "train", "detector", "--model", "ssdlite", "--steps", "10", "--batch", "2",
            "--checkpoint-every", "2", "--warmup", "1", "--no-progress", "--out", str(out)]


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_train_killed_at_random_moments_resumes_to_the_weights_of_an_unbroken_run(tmp_path):
    torch = pytest.importorskip("torch")
    pytest.importorskip("torchvision")
    ref, out = tmp_path / "ref", tmp_path / "run"
    t0 = time.perf_counter()
    r = subprocess.run(_train_cmd(ref), capture_output=True, text=True, timeout=900)
    full = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    rng = np.random.default_rng(7)
    steps_seen = []
    for _ in range(3):
        # killed mid-training: once the log shows a drawn number of new steps, after a drawn fraction of a step more
        log = out / "losses.csv"
        base = len(log.read_text().splitlines()) if log.exists() else 1
        until, extra = base + int(rng.integers(1, 3)), float(rng.uniform(0, 0.1))
        p = subprocess.Popen(_train_cmd(out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        while p.poll() is None and not (log.exists() and len(log.read_text().splitlines()) > until):
            time.sleep(0.01)
        time.sleep(extra)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        ck = out / "checkpoint.pt"
        if ck.exists():  # whatever the moment, the checkpoint on disk is a whole one
            steps_seen.append(int(torch.load(ck, weights_only=True)["step"]))
    r = subprocess.run(_train_cmd(out), capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    a = torch.load(ref / "weights.pt", weights_only=True)
    b = torch.load(out / "weights.pt", weights_only=True)
    sa, sb = a["state_dict"], b["state_dict"]
    assert sa.keys() == sb.keys()
    for k in sa:
        # (float16 weights: equal, or one rounding step apart where the sums' order differed)
        assert torch.allclose(sa[k].float(), sb[k].float(), rtol=2e-3, atol=1e-4), k
    log = (out / "losses.csv").read_text().splitlines()
    assert [line.split(",")[0] for line in log[1:]] == [str(i) for i in range(1, 11)]  # each step logged once
    print("train kills: checkpoint steps found", steps_seen, f"full run {full:.1f} s")


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_detect_killed_at_random_moments_leaves_the_old_or_the_new_file(tmp_path):
    pytest.importorskip("onnxruntime")
    import gpr3d

    dzt = str(__import__("pathlib").Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT")
    ref, out = tmp_path / "ref.json", tmp_path / "det.json"
    cmd = [sys.executable, "-m", "gpr3d", "detect", dzt, "--depth", "none"]
    t0 = time.perf_counter()
    assert subprocess.run([*cmd, "--out", str(ref)], capture_output=True, timeout=600).returncode == 0
    full = time.perf_counter() - t0
    old = {"input": "an earlier run", "targets": []}
    out.write_text(json.dumps(old))
    rng = np.random.default_rng(11)
    left = []
    for _ in range(3):
        p = subprocess.Popen([*cmd, "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(0.3, 1.3)) * full)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        got = json.loads(out.read_text())  # always a whole file
        assert got == old or got["targets"] == json.loads(ref.read_text())["targets"]
        left.append("old" if got == old else "new")
    assert subprocess.run([*cmd, "--out", str(out)], capture_output=True, timeout=600).returncode == 0
    assert json.loads(out.read_text())["targets"] == json.loads(ref.read_text())["targets"]
    assert [q.name for q in tmp_path.iterdir() if q.name.startswith(".")] == []  # no partial file stays
    print("detect kills left:", left, f"full run {full:.1f} s")


def _sim_cmd(out, n=10):
    return [sys.executable, "-m", "gpr3d", "simulate", "--engine", "forward", "--preset", "tiny", "--n", str(n),
            "--workers", "1", "--seed", "3", "--out", str(out), "--no-progress"]


def _samples(out) -> dict:
    """Each finished sample's B-scan, labels and scene (what a resumed set must share with an unbroken one)."""
    import gpr3d

    got = {}
    d = out / "samples"
    for p in sorted(d.iterdir()) if d.exists() else []:
        if not p.name.isdigit():
            continue
        assert sorted(q.name for q in p.iterdir()) == ["bscan.h5", "image.png", "labels.json", "scene.json"], p
        got[p.name] = (gpr3d.read(p / "bscan.h5").data, json.loads((p / "labels.json").read_text())["labels"],
                       (p / "scene.json").read_text())
    return got


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_simulate_killed_at_random_moments_resumes_to_the_set_of_an_unbroken_run(tmp_path):
    pytest.importorskip("distributed")
    import os

    ref, out = tmp_path / "ref", tmp_path / "run"
    t0 = time.perf_counter()
    r = subprocess.run(_sim_cmd(ref, 40), capture_output=True, text=True, timeout=600)
    full = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    want = _samples(ref)
    assert len(want) == 40
    rng = np.random.default_rng(5)
    seen = []
    for _ in range(3):
        # killed mid-build: once a drawn number of new samples is on disk, after a drawn fraction of a sample more
        base = len(_samples(out))
        # (a forward-model sample takes some 0.05 s once its kernels are compiled)
        until, extra = base + int(rng.integers(2, 10)), float(rng.uniform(0, 0.1))
        p = subprocess.Popen(_sim_cmd(out, 40), start_new_session=True, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
        d = out / "samples"
        while p.poll() is None and not (d.exists() and sum(q.name.isdigit() for q in d.iterdir()) >= until):
            time.sleep(0.02)
        time.sleep(extra)
        try:
            os.killpg(p.pid, signal.SIGKILL)  # the job and its Dask worker, at a drawn moment
        except ProcessLookupError:
            pass
        p.wait(timeout=60)
        got = _samples(out)  # every sample folder on disk is a whole one, and the unbroken run's
        for k, (data, labels, scene) in got.items():
            np.testing.assert_array_equal(data, want[k][0])
            assert (labels, scene) == want[k][1:], k
        seen.append((until - base, round(extra, 2), len(got)))
    r = subprocess.run(_sim_cmd(out, 40), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    got = _samples(out)
    assert got.keys() == want.keys()
    for k, (data, labels, scene) in got.items():
        np.testing.assert_array_equal(data, want[k][0])
        assert (labels, scene) == want[k][1:], k
    assert [q.name for q in (out / "samples").iterdir() if not q.name.isdigit()] == []  # no half-built sample
    m = json.loads((out / "manifest.json").read_text())
    assert [e["index"] for e in m["samples"]] == list(range(40))
    assert 0 < seen[0][2] < 40, seen  # the first kill came mid-build
    print("simulate kills (new samples waited for, s more, samples whole on disk):", seen, f"full run {full:.1f} s")


def _fuse_cmd(d, out):
    return [sys.executable, "-m", "gpr3d", "pose", "fuse", "--imu", str(d / "imu.csv"), "--odometry",
            str(d / "odometry.tum"), "--wheel", str(d / "wheel.csv"), "--rig", str(d / "rig.json"), "--out", str(out)]


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_pose_simulate_and_fuse_killed_at_random_moments_leave_the_old_or_the_new_result(tmp_path):
    rig = tmp_path / "rig"
    sim = [sys.executable, "-m", "gpr3d", "pose", "simulate", "--duration", "40", "--out", str(rig)]
    t0 = time.perf_counter()
    r = subprocess.run([*sim, "--seed", "1"], capture_output=True, text=True, timeout=600)
    full_sim = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    first = (rig / "imu.csv").read_text()
    rng = np.random.default_rng(13)
    left = []
    for seed in (2, 3):  # another seed each time: the file's content tells which run it came from
        p = subprocess.Popen([*sim, "--seed", str(seed)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(0.3, 1.0)) * full_sim)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        open_result(rig)
        check_result(rig)  # every file of one run, with the hashes its manifest gives
        left.append("old" if (rig / "imu.csv").read_text() == first else "new")
    r = subprocess.run([*sim, "--seed", "1"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert (rig / "imu.csv").read_text() == first  # the same line again: the same recordings
    check_result(rig)

    ref, out = tmp_path / "ref.tum", tmp_path / "fused.tum"
    t0 = time.perf_counter()
    r = subprocess.run(_fuse_cmd(rig, ref), capture_output=True, text=True, timeout=600)
    full = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    old = "# t tx ty tz qx qy qz qw\n0.0 0 0 0 0 0 0 1\n"
    out.write_text(old)
    for _ in range(3):
        p = subprocess.Popen(_fuse_cmd(rig, out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(0.3, 1.05)) * full)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        got = out.read_text()
        assert got in (old, ref.read_text())  # a whole file: the earlier one or the new one
        left.append("old" if got == old else "new")
    r = subprocess.run(_fuse_cmd(rig, out), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert out.read_text() == ref.read_text()
    assert [q.name for q in tmp_path.iterdir() if q.name.startswith(".")] == []
    assert [q.name for q in rig.iterdir() if q.name.startswith(".")] == []
    print("pose simulate then fuse kills left:", left, f"full runs {full_sim:.1f} s, {full:.1f} s")


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_dataset_pack_killed_at_random_moments_leaves_the_old_or_the_new_file(tmp_path):
    pytest.importorskip("distributed")
    src = tmp_path / "ds"
    r = subprocess.run(_sim_cmd(src, n=6), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    pack = [sys.executable, "-m", "gpr3d", "dataset", "pack", str(src)]
    ref, out = tmp_path / "ref.h5", tmp_path / "packed.h5"
    t0 = time.perf_counter()
    r = subprocess.run([*pack, str(ref)], capture_output=True, text=True, timeout=600)
    full = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    r = subprocess.run([*pack, str(out), "--n-samples", "64"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr  # an earlier, other pack in its place

    def rows(path):
        with h5py.File(path) as f:
            return f["data"].shape[-1]

    rng = np.random.default_rng(17)
    left = []
    for _ in range(3):
        p = subprocess.Popen([*pack, str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(0.3, 1.3)) * full)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        n = rows(out)  # a whole HDF5 file, the earlier pack (64 rows) or the new one
        assert n in (64, rows(ref))
        left.append("old" if n == 64 else "new")
    r = subprocess.run([*pack, str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    with h5py.File(out) as a, h5py.File(ref) as b:
        np.testing.assert_array_equal(a["data"][()], b["data"][()])
        assert a["labels_json"][()].tolist() == b["labels_json"][()].tolist()
    assert [q.name for q in tmp_path.iterdir() if q.name.startswith(".")] == []  # no partial file stays
    print("dataset pack kills left:", left, f"full run {full:.1f} s")


def _run_cmd(d, out, score=0.5):
    return [sys.executable, "-m", "gpr3d", "run", str(d / "line.h5"), "--poses", str(d / "walk.tum"), "--eps-r",
            "file", "--max-depth", "0.6", "--score", str(score), "--out", str(out)]


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_run_killed_at_random_moments_keeps_whole_stages_and_finishes_as_an_unbroken_run(line, tmp_path):
    pytest.importorskip("onnxruntime")
    from gpr3d.pipeline.run import STAGES, _Journal

    ref, out = tmp_path / "ref", tmp_path / "run"
    t0 = time.perf_counter()
    r = subprocess.run(_run_cmd(line, ref), capture_output=True, text=True, timeout=900)
    full = time.perf_counter() - t0
    assert r.returncode == 0, r.stderr
    rng = np.random.default_rng(23)
    seen = []
    for score in (0.45, 0.55, 0.6):  # another threshold each time: detection and what follows it are made again
        at = float(rng.uniform(0.1, 1.0)) * full
        p = subprocess.Popen(_run_cmd(line, out, score), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(at)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=60)
        j = _Journal(out)
        for stage, rec in j.stages.items():  # every stage the journal names is whole on disk: its files' hashes
            assert j.done(stage, rec["key"]), (at, stage)
        done = [s for s in STAGES if s in j.stages]
        assert done == list(STAGES)[: len(done)], done  # a stage is recorded only after the ones before it
        if (out / "reconstruction").exists():
            open_result(out / "reconstruction")
        seen.append((score, round(at, 1), done))
    r = subprocess.run(_run_cmd(line, out), capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    kept = r.stdout.count("kept from an earlier run")
    got = json.loads((out / "reconstruction" / "targets.json").read_text())
    assert got == json.loads((ref / "reconstruction" / "targets.json").read_text())
    assert json.loads((out / "detections.json").read_text())["targets"] == \
        json.loads((ref / "detections.json").read_text())["targets"]
    check_result(out / "reconstruction")
    assert [q.name for q in out.iterdir() if q.name.startswith(".")] == []
    print("run kills (--score, s after the start, stages whole on disk):", seen, f"; the re-run kept {kept} stage(s);",
          f"full run {full:.1f} s")
