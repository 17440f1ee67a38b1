"""gpr3d run: the whole system in one command gives the targets the separate commands give, and resumes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import gpr3d

DZT = Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT"


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "gpr3d", *map(str, args)], capture_output=True, text=True,
                          timeout=900)


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_run_on_the_real_dzt_finds_the_targets_of_reconstruct_with_the_detector_mask(tmp_path):
    pytest.importorskip("onnxruntime")
    r = run_cli("run", DZT, "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert "[3/3] reconstruction" in r.stdout and "report.html" in r.stdout
    ref = run_cli("reconstruct", DZT, "--mask", "detect", "--out", tmp_path / "rec")
    assert ref.returncode == 0, ref.stderr
    got = json.loads((tmp_path / "run" / "reconstruction" / "targets.json").read_text())
    assert got == json.loads((tmp_path / "rec" / "targets.json").read_text()) and got["targets"]
    a = json.loads((tmp_path / "run" / "reconstruction" / "config.json").read_text())
    b = json.loads((tmp_path / "rec" / "config.json").read_text())
    assert a["eps_r"] == b["eps_r"]  # the same estimate, carried from detections.json
    assert a["eps_r_source"].startswith("estimated (hybrid")
    again = run_cli("run", DZT, "--out", tmp_path / "run")
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("kept from an earlier run") == 3


@pytest.mark.parametrize("args, msg", [
    (["--score", "2"], "--score must lie in 0..1"),
    (["--trace-spacing", "0"], "--trace-spacing must be a distance"),
    (["--poses", "nosuch.tum"], "--poses nosuch.tum: no such file"),
    (["--odometry", "x.tum"], "give --imu"),
    (["--eps-r", "0.5"], "--eps-r must be a relative permittivity"),
    (["--spacing", "-1"], "--spacing must be"),
])
def test_wrong_arguments_are_one_line_before_any_work(tmp_path, args, msg):
    import contextlib
    import io

    from gpr3d.cli.main import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["run", str(DZT), "--out", str(tmp_path / "o"), *args])
    assert rc != 0 and msg in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1, err.getvalue()
    assert not (tmp_path / "o").exists()
