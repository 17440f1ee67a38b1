"""Atomic file writes: a reader never sees a half-written output."""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from glob import escape as glob_escape
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_text", "resume_log", "file_sha256"]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _remove_stale_parts(path: Path) -> None:
    """Remove the temporary files that earlier writes of ``path`` left when their process was killed (each names
    its writer's process id; a living writer's file is left alone)."""
    prefix = f".{path.name}."
    for p in path.parent.glob(f".{glob_escape(path.name)}.*-*.part*"):
        pid = p.name[len(prefix):].split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            with contextlib.suppress(OSError):
                p.unlink()


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one step.

    On an exception the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_parts(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}-", suffix=suffix or ".part", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp creates 0600 files: give the output the usual permissions
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def resume_log(path, step: int, header: str):
    """Open a training run's CSV log (first column: the step) for appending from ``step``.

    A new run (``step`` 0, or no log yet) starts the file with ``header``; a resumed one first drops the rows
    after ``step`` (those written between the last checkpoint and a kill), atomically, so that each step is
    logged once.
    """
    path = Path(path)
    if step == 0 or not path.exists():
        fh = open(path, "w")
        fh.write(header.rstrip("\n") + "\n")
        return fh
    lines = path.read_text().splitlines()
    kept = lines[:1] + [ln for ln in lines[1:] if ln.split(",", 1)[0].isdigit() and int(ln.split(",", 1)[0]) <= step]
    if len(kept) != len(lines):
        atomic_write_text(path, "\n".join(kept) + "\n")
    return open(path, "a")


def file_sha256(path) -> str:
    """SHA-256 of a file's bytes (hex), read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
