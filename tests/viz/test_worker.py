"""The figures' worker process: jobs run in another process and give back what they return or raise; a worker that
dies or hangs leaves the job to this process; the same files either way."""

import os
import time

import numpy as np
import pytest

from gpr3d.viz import worker as W

needs_fork = pytest.mark.skipif(not W._enabled(), reason="no fork here (or GPR3D_FIGURE_WORKER=0)")


def _pid_and(x):
    return os.getpid(), x


def _raise(msg):
    raise ValueError(msg)


def _die_unless(pid):
    if os.getpid() != pid:  # the worker: gone without a word
        os._exit(3)
    return "drawn here"


def _hang_unless(pid):
    if os.getpid() != pid:
        time.sleep(60)
    return "drawn here"


@needs_fork
def test_a_job_runs_in_the_worker_and_gives_back_its_value():
    with W.FigureWorker() as w:
        assert w.alive
        job = w.submit(_pid_and, [1, 2])
        pid, x = job()
        assert pid != os.getpid() and pid == w._proc.pid
        assert x == [1, 2]
        job = w.submit(_pid_and, "again")  # one job after another
        assert job() == (pid, "again")
        assert w.answered == 2


def test_without_a_worker_the_job_runs_here(monkeypatch):
    with W.FigureWorker(enabled=False) as w:
        assert not w.alive
        assert w.submit(_pid_and, 5)() == (os.getpid(), 5)
    monkeypatch.setenv("GPR3D_FIGURE_WORKER", "0")
    assert W.FigureWorker().enabled is False


@needs_fork
def test_a_job_that_does_not_pickle_runs_here_and_the_worker_stays():
    with W.FigureWorker() as w:
        job = w.submit(lambda x: (os.getpid(), x), 3)  # a lambda: no pickle
        assert job() == (os.getpid(), 3) and w.alive and w.answered == 0
        assert w.submit(_pid_and, 4)() == (w._proc.pid, 4)


@needs_fork
def test_what_the_job_raises_in_the_worker_is_raised_here():
    with W.FigureWorker() as w:
        job = w.submit(_raise, "no such colour map")
        with pytest.raises(ValueError, match="no such colour map"):
            job()
        assert w.submit(_pid_and, 1)()[0] == w._proc.pid  # and the worker goes on


@needs_fork
def test_a_worker_that_dies_or_hangs_leaves_the_job_to_this_process():
    with W.FigureWorker() as w:
        job = w.submit(_die_unless, os.getpid())
        assert job() == "drawn here"
        assert not w.alive and w.answered == 0
        assert w.submit(_pid_and, 2)() == (os.getpid(), 2)  # no worker left: here
    with W.FigureWorker() as w:
        w.patience_s = 0.5
        pid = w._proc.pid
        job = w.submit(_hang_unless, os.getpid())
        assert job() == "drawn here"
        assert not w.alive
        with pytest.raises(ProcessLookupError):  # killed and reaped
            os.kill(pid, 0)


@needs_fork
def test_the_worker_ends_with_its_block_even_after_an_error():
    with pytest.raises(RuntimeError):
        with W.FigureWorker() as w:
            pid = w._proc.pid
            w.submit(_hang_unless, os.getpid())  # still drawing when the command fails
            raise RuntimeError("the command failed")
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


@needs_fork
@pytest.mark.parametrize("noise", [False, True])
def test_the_result_folder_holds_the_same_figures_drawn_in_the_worker_or_here(tmp_path, noise):
    from gpr3d.core.grid import Grid3D
    from gpr3d.migration.reconstruct import Reconstruction
    from gpr3d.migration.targets import Target3D
    from gpr3d.pipeline.reconstruction import write_result

    g = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 50, 40, 20)
    env = np.random.default_rng(1).random(g.shape).astype(np.float32) * 0.2
    env[:, 20, 9] = 1.0
    t = Target3D(kind="line", points_xyz=[[0.0, 0.4, 0.18], [0.98, 0.4, 0.18]], score=1.0, depth_m=0.18)
    rec = Reconstruction(image=env, envelope=env, noise_map=0.5 * env if noise else None, fold=None, grid=g,
                         targets=[t], eps_r=9.0, config={"threshold": 0.3}, n_traces=10, timings_s={},
                         updates_per_s=None)
    here = write_result(rec, tmp_path / "here", source="s")
    with W.FigureWorker() as w:
        there = write_result(rec, tmp_path / "there", source="s", figures=w)
        assert w.answered == 1  # the figures were the worker's
    assert here == there and {"top.png", "front.png", "view3d.png"} <= set(here)
    for name in ("top.png", "front.png", "view3d.png"):
        assert (tmp_path / "here" / name).read_bytes() == (tmp_path / "there" / name).read_bytes(), name


def _touch(path, pid_file):
    path.write_text("written")
    pid_file.write_text(str(os.getpid()))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork here")
def test_a_forked_job_tells_whether_it_returned():
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        pid = W.fork_job(_touch, d / "out", d / "pid")
        assert pid is not None and W.wait_job(pid) is True
        assert (d / "out").read_text() == "written" and int((d / "pid").read_text()) == pid != os.getpid()
    assert W.wait_job(W.fork_job(_raise, "no")) is False  # raised: said by its exit status, not raised in it
    assert W.wait_job(W.fork_job(_die_unless, os.getpid())) is False  # (exit status 3)
    assert W.in_worker() is False


def _in_worker():
    return W.in_worker()


@needs_fork
def test_the_worker_knows_it_is_the_worker():
    with W.FigureWorker() as w:
        assert w.submit(_in_worker)() is True
    assert W.in_worker() is False


def _fork_a_hang():
    return W.fork_job(time.sleep, 60)


def _gone(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"  # (ended, not yet reaped)
    except OSError:
        return True


@needs_fork
def test_a_process_the_worker_forked_ends_with_the_worker():
    with W.FigureWorker() as w:
        pid = w.submit(_fork_a_hang)()
        assert isinstance(pid, int) and not _gone(pid)
    for _ in range(100):  # the worker ended with its block; what it forked follows it within moments
        if _gone(pid):
            break
        time.sleep(0.05)
    assert _gone(pid)


@needs_fork
def test_an_idle_worker_is_ended_at_once_not_waited_for():
    import signal

    with W.FigureWorker() as w:
        assert w.submit(_pid_and, 1)()[1] == 1
        proc = w._proc
    assert proc.exitcode == -signal.SIGKILL  # killed idle, not left to wind matplotlib down


@needs_fork
def test_a_worker_whose_command_is_killed_ends_with_it_and_writes_nothing_more(tmp_path):
    import signal
    import subprocess
    import sys

    done = tmp_path / "drawn.txt"
    script = f"""
import os, signal, sys, time
from pathlib import Path
from gpr3d.viz import worker as W

def slow_figure(path):
    time.sleep(2.0)
    Path(path).write_text("drawn")

w = W.FigureWorker().__enter__()
w.submit(slow_figure, {str(done)!r})
print(w._proc.pid, flush=True)
time.sleep(0.5)
os.kill(os.getpid(), signal.SIGKILL)  # the command killed while its figure is drawn
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert r.returncode == -signal.SIGKILL, r.stderr
    pid = int(r.stdout.split()[0])
    for _ in range(200):  # killed with its command (PR_SET_PDEATHSIG): gone within moments (10 s: a loaded host's
        if _gone(pid):    # teardown); without the signal it lives on to finish the drawing, and the file says so
            break
        time.sleep(0.05)
    assert _gone(pid)
    time.sleep(2.5)  # past the moment a drawing begun before the kill would have ended
    assert not done.exists()
