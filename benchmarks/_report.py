"""What the benchmark scripts share: the host CPU's name and writing a result table beside its command."""

from __future__ import annotations

import platform
import shlex
import sys
from pathlib import Path


def threads_from_argv(default: int = 2) -> None:
    """Set ``NUMBA_NUM_THREADS`` from ``--threads N`` on the command line (default ``default``): numba reads it when
    it is first imported, so a benchmark calls this before importing numba or gpr3d's kernels."""
    import os

    for i, a in enumerate(sys.argv):
        if a == "--threads" and i + 1 < len(sys.argv):
            os.environ["NUMBA_NUM_THREADS"] = sys.argv[i + 1]
    os.environ.setdefault("NUMBA_NUM_THREADS", str(default))


def _model_name() -> str:
    """The CPU's model name as the kernel reports it (``/proc/cpuinfo``), or "" where there is none."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def cpu_name() -> str:
    """The host CPU as LLVM names it (e.g. ``znver4``, ``sapphirerapids``), via numba, with the model name the
    kernel reports beside it where there is one (in a virtual machine LLVM may name an Intel Xeon ``rocketlake``):
    ``rocketlake (Intel(R) Xeon(R) Processor)``."""
    try:
        import numba.misc.numba_sysinfo as si

        name = si.get_sysinfo().get("CPU Name") or platform.processor() or platform.machine()
    except Exception:  # noqa: BLE001 - numba missing or its probe failing must not stop a benchmark
        name = platform.processor() or platform.machine()
    model = _model_name()
    return f"{name} ({model})" if model else name


def write_table(out_dir, name: str, table: str, script: str, argv=None) -> Path:
    """Print ``table`` and write it to ``out_dir/name`` with the command that reproduces it (its arguments quoted
    for a shell: ``--live-args "--weights W.onnx"`` stays one argument)."""
    print(table)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    args = sys.argv[1:] if argv is None else list(argv)
    path = out / name
    path.write_text(f"{table}\n\ncommand: python benchmarks/{script} {shlex.join(str(a) for a in args)}\n")
    return path
