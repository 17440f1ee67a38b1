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
    k = warmup.key()
    if set(warmup.GROUPS) <= warmup.done(k) or warmup.running(k) is not None:
        return None
    return subprocess.Popen([sys.executable, "-m", "gpr3d.cli._warm"], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            close_fds=True)


def build(group: str) -> None:
    """Compile one group's kernels (on inputs of a few voxels: numba keeps the machine code in its cache)."""
    from gpr3d.migration import _kernels

    path = _kernels.read_path()
    if group == "tiled":
        _kernels.tiled_adjoint(path, True)
    elif group == "simd":
        _kernels.simd_adjoint(path)
    elif group == "scalar":
        import numpy as np

        from gpr3d.core.grid import Grid3D
        from gpr3d.migration.operator import BackProjection

        one = np.zeros((1, 3))
        op = BackProjection(Grid3D(0.0, 0.0, 0.0, 0.1, 0.1, 0.1, 1, 1, 2), one, one, dt_s=1e-10, n_samples=4,
                            eps_r=4.0)
        op.simd = False  # (no aperture: untiled) the scalar adjoint, then the forward operator
        op.forward(op.adjoint(np.zeros((1, 4), np.float32)))
    else:
        raise ValueError(f"no kernel group {group!r}")


def main() -> int:
    """Compile every group not yet done, lowest priority, under the lock (another warm-up running: nothing)."""
    from gpr3d.core import warmup

    if not warmup.enabled() or not warmup.claim():
        return 0
    k = warmup.key()
    try:
        try:
            os.nice(10)  # the user's command comes first
        except OSError:  # pragma: no cover - a platform without nice
            pass
        for group in warmup.GROUPS:
            if group not in warmup.done(k):
                build(group)
                warmup.mark_done(group, k)
    finally:
        warmup.release(k)
    return 0


if __name__ == "__main__":
    sys.exit(main())
