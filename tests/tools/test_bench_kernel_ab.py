"""benchmarks/bench_kernel_ab.py refuses a wrong setting in one line, before it models or compiles anything."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(*args):
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_kernel_ab.py"), *args],
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("args, says", [
    ((), "--base REV is needed"),
    (("--base", "no-such-revision-xyz"), "--base 'no-such-revision-xyz' is not a commit of this repository"),
    (("--base", "HEAD", "--rounds", "0"), "--rounds and --threads must be >= 1, --traces >= 100"),
    (("--base", "HEAD", "--traces", "99"), "--rounds and --threads must be >= 1, --traces >= 100"),
    (("--base", "HEAD", "--out", "/proc/no/such/folder"), "--out /proc/no/such/folder: No such file or directory"),
])
def test_a_wrong_setting_is_one_line_naming_it(args, says):
    if args[:1] == ("--base",) and not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    r = _run(*args)
    assert r.returncode != 0 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert says in lines[-1] and "Traceback" not in r.stderr, r.stderr
