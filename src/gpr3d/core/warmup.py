"""Compiling the numba kernels off the user's path: the record of what a background warm-up has compiled.

numba compiles a kernel on its first call and keeps the machine code in its disk cache, so
every later process loads it in a fraction of a second; the first call on a fresh install
pays the compilation (tens of seconds for the migration kernels on two cores). gpr3d's
command line starts one background process per machine (``gpr3d.cli._warm``) that calls
the kernels on tiny inputs, group by group, while the command itself reads, processes and
detects. A process that reaches a kernel of a group the warm-up is still compiling waits for
it (:func:`wait`) and then loads the group from the cache, instead of compiling it a second
time beside it on the same cores.

The record lives beside numba's cache (``NUMBA_CACHE_DIR``, else the package's own
``__pycache__``): ``gpr3d-warm-KEY.json`` lists the groups done, ``gpr3d-warm-KEY.lock`` holds
the warm-up's process id while it runs. ``KEY`` changes with gpr3d's and numba's versions,
Python's, the CPU, and the kernels' sources, so an edited kernel is compiled again.
``GPR3D_WARMUP=0`` turns the background warm-up off.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import time
from pathlib import Path

__all__ = ["GROUPS", "enabled", "key", "record_dir", "done", "mark_done", "claim", "release", "running", "wait"]

_PKG = Path(__file__).resolve().parents[1]
#: the kernel groups, in the order the warm-up compiles them, each with the sources it depends on: the tiled back
#: projection, which every migration with an aperture (reconstruct's default) runs. The rarer kernels (no aperture,
#: the forward operator) compile on their first call: compiled in the background they would take a core from the
#: command that started the warm-up, which measured slower for it (benchmarks/results/bench_stages.md)
GROUPS = {"tiled": ("migration/_kernels.py", "migration/_simd.py", "core/raypath.py")}


def enabled() -> bool:
    """False when ``GPR3D_WARMUP`` is ``0`` (or numba's JIT is off: nothing to compile)."""
    return os.environ.get("GPR3D_WARMUP") != "0" and os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")


def key() -> str:
    """What the compiled code depends on: versions, CPU, thread count and the kernels' sources (16 hex digits)."""
    import llvmlite.binding as llb
    import numba

    from gpr3d import __version__

    parts = [__version__, numba.__version__, platform.python_version(), llb.get_host_cpu_name(),
             os.environ.get("NUMBA_NUM_THREADS", "")]
    h = hashlib.sha256(json.dumps(parts).encode())
    for rel in sorted({f for files in GROUPS.values() for f in files}):
        path = _PKG / rel
        h.update(path.read_bytes() if path.is_file() else rel.encode())
    return h.hexdigest()[:16]


def record_dir() -> Path:
    """Where numba keeps gpr3d's compiled kernels (and so this record): ``NUMBA_CACHE_DIR`` or the package's
    ``migration/__pycache__``."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    return Path(env) if env else _PKG / "migration" / "__pycache__"


def _paths() -> tuple[Path, Path]:
    d, k = record_dir(), key()
    return d / f"gpr3d-warm-{k}.json", d / f"gpr3d-warm-{k}.lock"


def done() -> set:
    """The groups already compiled into the cache (an unreadable record counts as none)."""
    rec, _ = _paths()
    try:
        return set(json.loads(rec.read_text())["done"])
    except (OSError, ValueError, KeyError, TypeError):
        return set()


def mark_done(group: str) -> None:
    """Add ``group`` to the record (written whole: a reader sees the old record or the new one)."""
    from gpr3d.core.atomic import atomic_write_text

    rec, _ = _paths()
    rec.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(rec, json.dumps({"done": sorted(done() | {group})}))


def _state(pid: int) -> str | None:
    """The process's state letter from ``/proc`` (``Z``: a zombie, finished but not yet reaped), or None."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            return f.read().rsplit(")", 1)[1].split()[0]  # after the name, which may hold ')'
    except (OSError, IndexError):
        return None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)  # signal 0: only asks whether the process exists
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: it exists
        pass
    return _state(pid) != "Z"


def running() -> int | None:
    """The process id of a warm-up running now, or None (a lock left by a dead one is removed)."""
    _, lock = _paths()
    try:
        text = lock.read_text()
    except OSError:
        return None
    try:
        pid = int(text.strip())
    except ValueError:  # a damaged lock (claim writes it whole): nobody holds it
        pid = 0
    if pid > 0 and _alive(pid):
        return pid
    try:
        lock.unlink()
    except OSError:
        pass
    return None


def claim(pid: int | None = None) -> bool:
    """Take the lock for a new warm-up (True), unless one runs or the record's folder cannot be written (False).
    The lock holds ``pid`` (default: this process's id) until :func:`release`: the command that starts the
    warm-up takes it for the child at once, so a kernel reached before the child is up already finds it running."""
    _, lock = _paths()
    running()  # a dead warm-up's lock is cleared first
    holder = os.getpid() if pid is None else pid
    tmp = lock.with_name(f"{lock.name}.{os.getpid()}")
    try:
        lock.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(str(holder))
        os.link(tmp, lock)  # appears whole, with the id in it, or not at all (another holds it)
    except OSError:
        return False
    finally:
        try:
            tmp.unlink()
        except OSError:
            pass
    return True


def release() -> None:
    """Remove the lock (the warm-up is over)."""
    _, lock = _paths()
    try:
        lock.unlink()
    except OSError:
        pass


def wait(group: str, *, timeout_s: float = 900.0, poll_s: float = 0.05, log=None) -> float:
    """Wait while a background warm-up is compiling ``group``; returns the seconds waited (0 when it is done,
    or no warm-up runs, or warm-ups are off: then the caller compiles as usual)."""
    if not enabled() or group not in GROUPS:
        return 0.0
    if group in done() or running() in (None, os.getpid()):  # (the warm-up itself does not wait for itself)
        return 0.0
    from gpr3d.core.timing import stage

    if log is not None:
        log(f"waiting for the background compilation of gpr3d's {group} kernels (once per machine)")
    t0 = time.monotonic()
    with stage("compile (background warm-up)"):
        while time.monotonic() - t0 < timeout_s:
            if group in done() or running() is None:
                break
            time.sleep(poll_s)
    return time.monotonic() - t0
