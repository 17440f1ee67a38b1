"""benchmarks/bench_window.py refuses a wrong setting in one line, before it loads a model or makes a window."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(*args):
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_window.py"), *args],
                          capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("args, says", [
    (("--windows", "0"), "--windows must lie in 1..500, got 0"),
    (("--rounds", "101"), "--rounds must lie in 1..100, got 101"),
    (("--out", "/proc/no/such/folder"), "--out /proc/no/such/folder: No such file or directory"),
    (("--out", "{file}"), "not a folder"),
    (("--base", "no-such-revision-xyz"), "--base no-such-revision-xyz: "),
    (("--other", "/no/such.onnx"), "--other /no/such.onnx: no such file"),
    (("--name", "../x.md"), "--name ../x.md: a file name ending in .md"),
    (("--base", "HEAD", "--other", "{file}"), "--base and --other: give one graph to time against"),
])
def test_a_wrong_setting_is_one_line_naming_it(tmp_path, args, says):
    if args[:1] == ("--base",) and not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    (tmp_path / "f").write_text("")
    r = _run(*(a.replace("{file}", str(tmp_path / "f")) for a in args))
    assert r.returncode != 0 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in r.stderr, r.stderr
