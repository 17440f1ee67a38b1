"""The background warm-up of the numba kernels (:mod:`gpr3d.core.warmup`): started by the commands that migrate,
run as ``python -m gpr3d.cli._warm``, once per machine (and again after an upgrade or a kernel's change)."""

from __future__ import annotations

import os
import subprocess
import sys

#: the commands whose work reaches the migration kernels: they start the warm-up when it has not run
COMMANDS = ("demo", "reconstruct", "run")


def start_background(command: str):
    """Start the warm-up in a process of its own (a new session: it outlives the command, and a Ctrl-C of the
    command does not stop it) when ``command`` needs the kernels and they are not compiled yet; returns the
    process or None."""
    from gpr3d.core import warmup

    if command not in COMMANDS or not warmup.enabled():
        return None
    if set(warmup.GROUPS) <= warmup.done() or warmup.running() is not None:
        return None
    proc = subprocess.Popen([sys.executable, "-m", "gpr3d.cli._warm"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            close_fds=True)
    # the lock taken for the child now, not when it is up (its start-up, a second or more on a busy machine, could
    # let the command reach the kernels first and compile them beside it); the child may have taken it already
    warmup.claim(proc.pid)
    return proc


def build(group: str) -> None:
    """Compile one group's kernels (on inputs of a few voxels: numba keeps the machine code in its cache)."""
    from gpr3d.migration import _kernels

    if group != "tiled":
        raise ValueError(f"no kernel group {group!r}")
    _kernels.tiled_adjoint(_kernels.read_path(), True)  # (the fold is an argument: one build for both)


def main() -> int:
    """Compile every group not yet done, lowest priority, under the lock (another warm-up running: nothing)."""
    from gpr3d.core import warmup

    if not warmup.enabled():
        return 0
    if warmup.running() != os.getpid() and not warmup.claim():  # (the starting command took it for us, or not)
        return 0
    try:
        try:
            os.nice(10)  # the user's command comes first
        except OSError:  # pragma: no cover - a platform without nice
            pass
        for group in warmup.GROUPS:
            if group not in warmup.done():
                build(group)
                warmup.mark_done(group)
    finally:
        warmup.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
