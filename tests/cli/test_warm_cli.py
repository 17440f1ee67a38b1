"""The background warm-up of the numba kernels (gpr3d.cli._warm): who starts it, what it records, and a command
that meets it (slow: the real compilation)."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from gpr3d.cli import _warm
from gpr3d.core import warmup


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "nc"))
    monkeypatch.setenv("GPR3D_WARMUP", "1")
    return tmp_path / "nc"


def test_only_migrating_commands_start_it_and_only_when_needed(cache, monkeypatch):
    started = []
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])  # stands for the warm-up

    class FakePopen:
        pid = child.pid

        def __init__(self, cmd, **kw):
            started.append((cmd, kw))

    monkeypatch.setattr(_warm.subprocess, "Popen", FakePopen)
    for cmd in ("info", "detect", "train", "show"):
        assert _warm.start_background(cmd) is None
    assert started == [] and warmup.running() is None
    try:
        assert isinstance(_warm.start_background("reconstruct"), FakePopen)
        # the lock is the child's from the start: a kernel reached before the child is up waits for it
        assert warmup.running() == child.pid
    finally:
        child.kill()
        child.wait()
    cmd, kw = started[0]
    assert cmd == [sys.executable, "-m", "gpr3d.cli._warm"]
    assert kw["start_new_session"] and kw["stdout"] == kw["stderr"] == kw["stdin"] == subprocess.DEVNULL
    assert _warm.COMMANDS == ("demo", "reconstruct", "run")
    assert warmup.running() is None  # (the child gone: its lock cleared)
    for g in warmup.GROUPS:
        warmup.mark_done(g)
    assert _warm.start_background("demo") is None  # all compiled already
    warmup._paths()[0].unlink()
    assert warmup.claim()
    assert _warm.start_background("run") is None  # one is running (this process holds the lock)
    warmup.release()
    monkeypatch.setenv("GPR3D_WARMUP", "0")
    assert _warm.start_background("run") is None
    assert len(started) == 1


def test_the_warm_up_builds_each_group_not_done_in_order_and_lets_go_of_the_lock(cache, monkeypatch):
    built = []

    def build(group):
        assert warmup.running() == os.getpid()  # under the lock
        built.append(group)

    monkeypatch.setattr(_warm, "build", build)
    monkeypatch.setattr(os, "nice", lambda n: built.append(("nice", n)))
    monkeypatch.setattr(warmup, "GROUPS", {"tiled": (), "other": (), "third": ()})
    warmup.mark_done("other")
    assert _warm.main() == 0
    assert built == [("nice", 10), "tiled", "third"]
    assert warmup.done() == {"tiled", "other", "third"} and warmup.running() is None
    # the lock already taken for this process by the command that started it: it builds under that lock
    warmup._paths()[0].unlink()
    built.clear()
    assert warmup.claim(os.getpid())
    assert _warm.main() == 0
    assert built == [("nice", 10), "tiled", "other", "third"] and warmup.running() is None
    # a warm-up already running: this one does nothing
    built.clear()
    warmup._paths()[0].unlink()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        warmup._paths()[1].write_text(str(sleeper.pid))
        assert _warm.main() == 0 and built == []
    finally:
        sleeper.kill()
        sleeper.wait()
    # a failing build: the lock is let go all the same, the group not recorded
    monkeypatch.setattr(_warm, "build", lambda g: 1 / 0)
    warmup.release()
    with pytest.raises(ZeroDivisionError):
        _warm.main()
    assert warmup.running() is None and warmup.done() == set()
    built.clear()
    monkeypatch.setenv("GPR3D_WARMUP", "0")
    monkeypatch.setattr(_warm, "build", build)
    assert _warm.main() == 0 and built == []


def test_an_unknown_group_is_refused_and_tiled_builds_the_tiled_kernel(cache, monkeypatch):
    from gpr3d.migration import _kernels

    with pytest.raises(ValueError, match="no kernel group 'fast'"):
        _warm.build("fast")
    asked = []
    monkeypatch.setattr(_kernels, "tiled_adjoint", lambda path, fold=False: asked.append((path, fold)))
    monkeypatch.setattr(_kernels, "read_path", lambda: 7)
    _warm.build("tiled")
    assert asked == [(7, True)]
    assert list(warmup.GROUPS) == ["tiled"]


@pytest.mark.slow
def test_a_first_reconstruct_meets_the_warm_up_and_gives_the_same_volume(tmp_path):
    """A fresh numba cache: ``gpr3d reconstruct`` starts the warm-up, waits for its tiled kernel (a row of its own in
    the timings, no compilation of that kernel in the command) and writes the volume a run without the warm-up
    writes; the warm-up goes on to record every group."""
    from gpr3d.io.volume import read_volume
    from tests.conftest import pipe_walk_files

    d = tmp_path / "walk"
    d.mkdir()
    pipe_walk_files(d, 600)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "nc"), "GPR3D_WARMUP": "1"}
    base = [sys.executable, "-m", "gpr3d"]
    args = ["reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--eps-r", "file", "--max-depth", "0.6"]
    r = subprocess.run([*base, "--timings", tmp_path / "t.json", *args, "--out", tmp_path / "a"], env=env,
                       capture_output=True, text=True, timeout=1500)
    assert r.returncode == 0, r.stderr
    stages = json.loads((tmp_path / "t.json").read_text())["stages"]
    assert stages["compile (background warm-up)"] > 0
    k_env = {"NUMBA_CACHE_DIR": env["NUMBA_CACHE_DIR"], "GPR3D_WARMUP": "1"}
    check = ("from gpr3d.core import warmup; import json; "
             "print(json.dumps([sorted(warmup.done()), warmup.running()]))")
    deadline = time.monotonic() + 1200
    while True:
        out = subprocess.run([sys.executable, "-c", check], env={**os.environ, **k_env}, capture_output=True,
                             text=True, check=True).stdout
        done, pid = json.loads(out)
        if pid is None or time.monotonic() > deadline:
            break
        time.sleep(1)
    assert done == sorted(warmup.GROUPS) and pid is None
    r2 = subprocess.run([*base, *args, "--out", tmp_path / "b"], env={**env, "GPR3D_WARMUP": "0",
                        "NUMBA_CACHE_DIR": str(tmp_path / "nc2")}, capture_output=True, text=True, timeout=1500)
    assert r2.returncode == 0, r2.stderr
    a, b = read_volume(tmp_path / "a" / "volume.h5"), read_volume(tmp_path / "b" / "volume.h5")
    np.testing.assert_array_equal(a.arrays["envelope"], b.arrays["envelope"])
    assert json.loads((tmp_path / "a" / "targets.json").read_text()) == \
        json.loads((tmp_path / "b" / "targets.json").read_text())
