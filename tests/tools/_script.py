"""Run a script of ``benchmarks/`` as a user would, for the tests of its one-line refusals."""

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
