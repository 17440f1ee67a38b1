"""Run a script of ``benchmarks/`` as a user would, for the tests of its one-line refusals, or load one (or a tool of
``tools/``) as a module."""

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def refusal(script: str, *args: str, timeout: float = 120) -> str:
    """The last line ``benchmarks/SCRIPT`` writes to stderr when it refuses ``args``: it must exit 2 (argparse's
    code), print nothing on stdout and no traceback."""
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], capture_output=True, text=True,
                       timeout=timeout)
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr, r.stderr
    return r.stderr.strip().splitlines()[-1]


def load_script(relative: str):
    """The script ``ROOT / relative`` (e.g. ``benchmarks/eval_duplicates.py``) loaded as a module of its file's name,
    its ``main`` not run."""
    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
