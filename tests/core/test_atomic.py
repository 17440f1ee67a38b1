"""Atomic writes and the training logs resumed after a kill."""


def test_a_resumed_log_drops_the_rows_after_its_checkpoint(tmp_path):
    from gpr3d.core.atomic import resume_log

    p = tmp_path / "losses.csv"
    with resume_log(p, 0, "step,loss\n") as fh:  # a new run: the header, once
        fh.write("1,0.9\n2,0.8\n3,0.7\n4,0.6\n")
    # killed after step 4, checkpoint at 2: steps 3 and 4 will be done again
    with resume_log(p, 2, "step,loss") as fh:
        fh.write("3,0.71\n")
    assert p.read_text() == "step,loss\n1,0.9\n2,0.8\n3,0.71\n"
    with resume_log(p, 3, "step,loss") as fh:  # nothing after the checkpoint: the file as it was, appended to
        fh.write("4,0.5\n")
    assert p.read_text() == "step,loss\n1,0.9\n2,0.8\n3,0.71\n4,0.5\n"
    with resume_log(p, 0, "step,loss") as fh:  # step 0: a new run starts the log again
        pass
    assert p.read_text() == "step,loss\n"
    q = tmp_path / "none.csv"
    with resume_log(q, 5, "step,loss") as fh:  # a resumed run whose log was removed: a new log
        fh.write("6,0.1\n")
    assert q.read_text() == "step,loss\n6,0.1\n"


def test_a_killed_writer_s_temporary_file_is_removed_by_the_next_write(tmp_path):
    import os
    import subprocess
    import sys

    from gpr3d.core.atomic import atomic_path, atomic_write_text

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()  # a process id that has ended
    stale = tmp_path / f".det.json.{dead}-x1y2.part"
    stale.write_text("half")
    writer = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])  # (our own child: a wrong
    live = tmp_path / f".det.json.{writer.pid}-a1b2.part"  # signal may hit it, never the test runner)
    live.write_text("writing")  # a writer still running: left alone
    other = tmp_path / f".other.json.{dead}-c3d4.part"  # another file's: not this write's business
    other.write_text("half")
    try:
        atomic_write_text(tmp_path / "det.json", "{}")
    finally:
        writer.kill()
        writer.wait()
    assert (tmp_path / "det.json").read_text() == "{}"
    assert not stale.exists() and live.exists() and other.exists()
    with atomic_path(tmp_path / "v.h5", suffix=".h5.part") as tmp:  # the writer's own name carries its pid
        assert tmp.name.startswith(f".v.h5.{os.getpid()}-") and tmp.name.endswith(".h5.part")
        tmp.write_text("x")


def test_file_sha256_is_hashlib_s_of_the_bytes(tmp_path):
    import hashlib

    from gpr3d.core.atomic import file_sha256

    data = bytes(range(256)) * 9000  # over two 1 MiB blocks
    (tmp_path / "b").write_bytes(data)
    assert file_sha256(tmp_path / "b") == hashlib.sha256(data).hexdigest()
    (tmp_path / "e").write_bytes(b"")
    assert file_sha256(tmp_path / "e") == hashlib.sha256(b"").hexdigest()


def test_resume_log_by_hand_at_its_edges(tmp_path):
    from gpr3d.core.atomic import resume_log

    p = tmp_path / "l.csv"
    with resume_log(p, 0, "step,loss,terms \n") as fh:  # the header as given, one newline
        fh.write("1,0.9,a=1\n2,0.8,a=2\n")
    assert p.read_text() == "step,loss,terms \n1,0.9,a=1\n2,0.8,a=2\n"
    with resume_log(p, 1, "step,loss,terms") as fh:  # checkpoint at step 1: row 1 stays, row 2 goes
        fh.write("2,0.7,a=3\n")
    assert p.read_text() == "step,loss,terms \n1,0.9,a=1\n2,0.7,a=3\n"


def test_stale_parts_edges(tmp_path, monkeypatch):
    import os
    import subprocess
    import sys
    from pathlib import Path

    from gpr3d.core.atomic import atomic_write_text

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    odd = tmp_path / f".det.json.{dead}-x1-y2.part"  # a dash inside the random part: the pid is before the first
    odd.write_text("half")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])  # dies on any signal sent
    mine = tmp_path / f".det.json.{live.pid}-a1b2.part"
    mine.write_text("writing")
    try:
        atomic_write_text(tmp_path / "det.json", "{}")
        assert not odd.exists() and mine.exists()
        assert live.poll() is None  # asked whether it lives (signal 0), not signalled
    finally:
        live.kill()
        live.wait()
    # another user's writer (PermissionError from the probe) counts as alive; a file that cannot be removed is left
    real_kill = os.kill

    def denied(pid, sig):
        raise PermissionError

    monkeypatch.setattr(os, "kill", denied)
    atomic_write_text(tmp_path / "det.json", "{}")
    assert mine.exists()
    monkeypatch.setattr(os, "kill", real_kill)
    stuck = tmp_path / f".det.json.{dead}-c3d4.part"
    stuck.write_text("half")
    real_unlink = Path.unlink

    def refuse(self, *a, **k):
        if self.name == stuck.name:
            raise OSError("read-only")
        return real_unlink(self, *a, **k)

    monkeypatch.setattr(Path, "unlink", refuse)
    atomic_write_text(tmp_path / "det.json", '{"a": 1}')
    assert (tmp_path / "det.json").read_text() == '{"a": 1}' and stuck.exists()
