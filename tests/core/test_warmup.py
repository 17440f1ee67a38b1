"""gpr3d.core.warmup: the record of the background compilation, its lock, and the wait for it."""

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from gpr3d.core import warmup


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "nc"))
    monkeypatch.setenv("GPR3D_WARMUP", "1")
    return tmp_path / "nc"


def test_the_record_lives_in_numba_s_cache_and_lists_the_groups_done(cache):
    assert warmup.record_dir() == cache
    k = warmup.key()
    assert len(k) == 16 and int(k, 16) >= 0 and warmup.key() == k
    assert warmup.done() == set()
    warmup.mark_done("tiled")
    warmup.mark_done("other")
    warmup.mark_done("tiled")
    assert warmup.done() == {"tiled", "other"}
    assert json.loads((cache / f"gpr3d-warm-{k}.json").read_text()) == {"done": ["other", "tiled"]}
    (cache / f"gpr3d-warm-{k}.json").write_text("{not json")
    assert warmup.done() == set()  # a damaged record: nothing counts as done
    (cache / f"gpr3d-warm-{k}.json").write_text("[1, 2]")
    assert warmup.done() == set()
    for bad in ("{}", '{"done": null}', '{"done": 3}'):
        (cache / f"gpr3d-warm-{k}.json").write_text(bad)
        assert warmup.done() == set(), bad


def test_the_record_s_folder_is_made_with_its_parents(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "a" / "b" / "c"))
    warmup.mark_done("tiled")
    assert warmup.done() == {"tiled"}
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "d" / "e"))
    assert warmup.claim() and (tmp_path / "d" / "e").is_dir()
    warmup.release()


def test_without_numba_cache_dir_the_record_sits_beside_the_kernels(monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    import gpr3d.migration._kernels as kernels

    assert warmup.record_dir() == Path(kernels.__file__).resolve().parent / "__pycache__"


def test_the_key_follows_the_kernels_sources_versions_and_threads(cache, monkeypatch, tmp_path):
    k = warmup.key()
    pkg = tmp_path / "pkg"
    for rel in {f for files in warmup.GROUPS.values() for f in files}:
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_bytes((warmup._PKG / rel).read_bytes())
    monkeypatch.setattr(warmup, "_PKG", pkg)
    assert warmup.key() == k  # the same sources: the same key
    (pkg / "migration" / "_simd.py").write_text((pkg / "migration" / "_simd.py").read_text() + "\n# edited\n")
    k2 = warmup.key()
    assert k2 != k
    monkeypatch.setenv("NUMBA_NUM_THREADS", "7")
    k3 = warmup.key()
    assert k3 not in (k, k2)
    monkeypatch.setenv("NUMBA_NUM_THREADS", "")
    empty = warmup.key()
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    assert warmup.key() == empty != k3  # unset counts as empty
    monkeypatch.setattr("gpr3d.__version__", "9.9.9")
    assert warmup.key() not in (k, k2, empty)
    # a source that is missing counts by its name
    monkeypatch.setattr(warmup, "GROUPS", {"g": ("migration/none.py",)})
    a = warmup.key()
    monkeypatch.setattr(warmup, "GROUPS", {"g": ("migration/other.py",)})
    assert warmup.key() != a


def test_enabled_by_the_environment(monkeypatch):
    monkeypatch.delenv("GPR3D_WARMUP", raising=False)
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    assert warmup.enabled()  # on unless turned off
    for v in ("", "0"):
        monkeypatch.setenv("NUMBA_DISABLE_JIT", v)
        assert warmup.enabled()
    monkeypatch.delenv("NUMBA_DISABLE_JIT")
    monkeypatch.setenv("GPR3D_WARMUP", "1")
    assert warmup.enabled()
    monkeypatch.setenv("GPR3D_WARMUP", "0")
    assert not warmup.enabled()
    monkeypatch.setenv("GPR3D_WARMUP", "1")
    monkeypatch.setenv("NUMBA_DISABLE_JIT", "1")
    assert not warmup.enabled()


def test_one_lock_at_a_time_and_a_dead_holder_s_lock_is_cleared(cache):
    assert warmup.running() is None
    assert warmup.claim()
    assert warmup.running() == os.getpid()
    assert not warmup.claim()  # held by a live process
    warmup.release()
    assert warmup.running() is None and warmup.claim()
    warmup.release()
    # a lock left by a process that died: cleared, and claimable again
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    _, lock = warmup._paths()
    lock.write_text(str(dead.pid))
    assert warmup.running() is None and not lock.exists()
    lock.write_text("garbage")
    assert warmup.running() is None and warmup.claim()
    warmup.release()
    warmup.release()  # twice: nothing to remove, no error
    # taken for another (live) process: it holds the lock, this one does not
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert warmup.claim(other.pid) and warmup.running() == other.pid
        assert not warmup.claim() and not warmup.claim(os.getpid())
    finally:
        other.kill()
        other.wait()
    assert warmup.running() is None


def test_asking_whether_the_holder_lives_does_not_signal_it(cache):
    # (hang-up restored to its default, which ends the process: under nohup it would be ignored)
    code = "import signal, time; signal.signal(signal.SIGHUP, signal.SIG_DFL); time.sleep(60)"
    sleeper = subprocess.Popen([sys.executable, "-c", code])
    time.sleep(0.5)  # its handler set
    try:
        _, lock = warmup._paths()
        lock.parent.mkdir(parents=True)
        lock.write_text(str(sleeper.pid))
        for _ in range(3):
            assert warmup.running() == sleeper.pid
        time.sleep(0.2)
        assert sleeper.poll() is None  # still running: asked with signal 0, never sent one
        lock.write_text("1")  # process 1 is always there
        assert warmup.running() == 1
    finally:
        sleeper.kill()
        sleeper.wait()


def test_someone_else_s_process_counts_as_alive_and_a_name_holding_parentheses_is_read_right(cache, monkeypatch):
    def refused(pid, sig):
        raise PermissionError(1, "not yours")

    monkeypatch.setattr(warmup.os, "kill", refused)
    assert warmup._alive(os.getpid())
    monkeypatch.undo()
    # a process whose name reads like a zombie's state: 'a) Z (b' (the state is after the last ')')
    code = "open('/proc/self/comm', 'w').write('a) Z (b'); import time; time.sleep(60)"
    odd = subprocess.Popen([sys.executable, "-c", code])
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and "Z (b" not in open(f"/proc/{odd.pid}/stat").read():
            time.sleep(0.02)
        assert warmup._state(odd.pid) in ("S", "R") and warmup._alive(odd.pid)
    finally:
        odd.kill()
        odd.wait()
    assert warmup._state(odd.pid) is None  # reaped: gone


def test_a_zombie_holder_is_not_running(cache):
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:  # exited, not yet reaped: a zombie
        with open(f"/proc/{child.pid}/stat") as f:
            if f.read().rsplit(")", 1)[1].split()[0] == "Z":
                break
        time.sleep(0.02)
    _, lock = warmup._paths()
    lock.parent.mkdir(parents=True)
    lock.write_text(str(child.pid))
    assert warmup.running() is None
    child.wait()


def test_wait_returns_at_once_when_done_when_none_runs_for_itself_and_when_off(cache, monkeypatch):
    monkeypatch.setattr(warmup, "GROUPS", {**warmup.GROUPS, "simd": (), "scalar": ()})
    assert warmup.wait("tiled") == 0.0  # no warm-up
    assert warmup.claim()  # this process is the warm-up: it does not wait for itself
    assert warmup.wait("tiled") == 0.0
    warmup.release()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        _, lock = warmup._paths()
        lock.write_text(str(sleeper.pid))
        warmup.mark_done("tiled")
        assert warmup.wait("tiled") == 0.0  # done already
        t = time.monotonic()
        assert warmup.wait("fourier") == 0.0  # a group the warm-up does not build: no wait for it
        assert time.monotonic() - t < 1.0
        monkeypatch.setenv("GPR3D_WARMUP", "0")
        assert warmup.wait("simd") == 0.0  # warm-ups off: the caller compiles
    finally:
        sleeper.kill()
        sleeper.wait()


def test_wait_lasts_until_the_group_is_done_or_the_warm_up_ends(cache, monkeypatch):
    from gpr3d.core.timing import collect

    monkeypatch.setattr(warmup, "GROUPS", {**warmup.GROUPS, "simd": (), "scalar": ()})

    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        _, lock = warmup._paths()
        lock.parent.mkdir(parents=True)
        lock.write_text(str(sleeper.pid))
        said = []
        threading.Timer(0.3, warmup.mark_done, args=("simd",)).start()
        with collect(compile_times=False) as t:
            waited = warmup.wait("simd", log=said.append)
        assert 0.25 <= waited < 1.0  # polled often (every 0.05 s by default), not after a second
        assert said == ["waiting for the background compilation of gpr3d's simd kernels (once per machine)"]
        assert t.seconds["compile (background warm-up)"] == pytest.approx(waited, abs=0.05)
        # another group: the warm-up ends (its process dies) before it is done
        threading.Timer(0.6, sleeper.kill).start()
        waited = warmup.wait("scalar")
        assert 0.5 <= waited < 30 and "scalar" not in warmup.done()
        # and a wait that runs out
        sleeper2 = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
        lock.write_text(str(sleeper2.pid))
        assert 0.3 <= warmup.wait("scalar", timeout_s=0.3) < 10
        sleeper2.kill()
        sleeper2.wait()
    finally:
        sleeper.kill()
        sleeper.wait()
