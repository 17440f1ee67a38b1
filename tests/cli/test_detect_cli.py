"""gpr3d detect / reconstruct --mask detect: the file contract, real recordings, and one-line errors."""

import json

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("torchvision")

from tests.cli.test_cli import run_cli  # noqa: E402
from tests.conftest import real_file  # noqa: E402


def test_detect_on_the_real_dzt_writes_the_contract(tmp_path):
    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out, png = tmp_path / "det.json", tmp_path / "det.png"
    r = run_cli("detect", src, "--out", out, "--overlay", png)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert d["n_traces"] == 1040 and d["dt_s"] == pytest.approx(48e-9 / 512)
    assert d["input"] == str(src)
    for t in d["targets"]:
        i0, t0, i1, t1 = t["box"]
        assert 0 <= i0 <= t["apex_trace"] <= i1 <= 1039
        assert 0 <= t0 <= t["apex_time_s"] <= t1 <= 511 * d["dt_s"]  # seconds from the first sample
        assert 0.5 <= t["score"] <= 1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"{len(d['targets'])} targets in 1040 traces" in r.stdout


@pytest.mark.parametrize("args, msg", [
    (["--score", "2"], "--score must lie in 0..1"),
    (["--weights", "{junk}"], "not a readable weights file"),
    (["--out", "{txt}"], "expected a .json file"),
])
def test_detect_bad_arguments_one_line(tmp_path, args, msg):
    from gpr3d.core.survey import Survey

    src = tmp_path / "s.h5"
    Survey(data=np.random.default_rng(0).normal(size=(50, 128)).astype(np.float32), dt_s=1e-10).save(src)
    (tmp_path / "junk.pt").write_bytes(b"junk")
    args = [a.format(junk=tmp_path / "junk.pt", txt=tmp_path / "x.txt") for a in args]
    base = ["detect", src, "--out", tmp_path / "d.json"]
    if "--out" in args:
        base = ["detect", src]
    r = run_cli(*base, *args)
    assert r.returncode == 1
    assert msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
