"""benchmarks/eval_pgpr.py names a P-GPR folder it cannot read in one line, before it loads a detector."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(*args):
    return subprocess.run([sys.executable, str(ROOT / "benchmarks" / "eval_pgpr.py"), "default", *args],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("make, args, says", [
    ((), ("--pgpr", "{tmp}/absent"), "--pgpr {tmp}/absent: no val/ folder in it (P-GPR's train/ and val/)"),
    (("val",), ("--pgpr", "{tmp}", "--split", "val,test"), "--pgpr {tmp}: no test/ folder in it"),
    (("val",), ("--pgpr", "{tmp}"), "val: not a YOLO dataset: no data.yaml and no images/ folder"),
])
def test_a_p_gpr_folder_it_cannot_read_is_one_line(tmp_path, make, args, says):
    for part in make:
        (tmp_path / part).mkdir()
    r = _run(*(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert r.returncode == 2 and r.stdout == "" and "Traceback" not in r.stderr, r.stderr
    assert says.replace("{tmp}", str(tmp_path)) in r.stderr.strip().splitlines()[-1]
