"""benchmarks/bench_pose.py refuses a wrong setting in one line, before it simulates or fuses anything."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("args, says", [
    (("--repeat", "0"), "--repeat must be 1 or more, got 0"),
    (("--seconds", "5"), "--seconds must lie in 10..3600, got 5"),
    (("--seconds", "nan"), "--seconds must lie in 10..3600, got nan"),
    (("--out", "{file}"), "not a folder"),
    (("--out", "/proc/no/such/folder"), "--out /proc/no/such/folder: No such file or directory"),
])
def test_a_wrong_setting_is_one_line_naming_it(tmp_path, args, says):
    (tmp_path / "f").write_text("")
    r = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_pose.py"),
                        *(a.replace("{file}", str(tmp_path / "f")) for a in args)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0] and "Traceback" not in r.stderr, r.stderr
