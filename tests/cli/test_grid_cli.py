"""gpr3d grid and gpr3d cscan: line files in, one survey and C-scans out."""

import json

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.cli.main import main
from gpr3d.io.volume import read_cscan
from tests.conftest import real_file


@pytest.fixture(scope="module")
def real_lines():
    try:
        return [real_file(f"gpro_sns_100MHz_grid/XLINE{k:02d}.DT1") for k in (0, 1, 2, 3)]
    except Exception:  # noqa: BLE001
        pytest.skip("../shared/data/real is absent")


def test_grid_then_cscan_on_real_lines(real_lines, tmp_path, capsys):
    assert main([*map(str, ["grid", *real_lines, "--spacing", "0.2", "--serpentine", "--steps", "time_zero",
                            "dewow", "--out", tmp_path / "g.h5"])]) == 0
    import gpr3d

    g = Survey.load(tmp_path / "g.h5")
    counts = [gpr3d.read(f).n_traces for f in real_lines]
    first = g.metadata["grid"]["first_trace"]
    assert first == list(np.cumsum([0, *counts[:-1]])) and g.n_traces == sum(counts)
    np.testing.assert_allclose(np.unique(np.round(g.positions_xyz[:, 1], 6)), [0.0, 0.2, 0.4, 0.6])
    # line 1 walked back: x falls along it
    seg = g.positions_xyz[first[1]:first[2], 0]
    assert seg[0] > seg[-1] and seg[-1] == pytest.approx(0.0, abs=1e-6)
    assert main(["cscan", str(tmp_path / "g.h5"), "--window-ns", "10", "--cell", "0.1", "--eps-r", "12",
                 "--out", str(tmp_path / "c")]) == 0
    cs = read_cscan(tmp_path / "c" / "cscan.h5")
    assert (tmp_path / "c" / "cscan.png").stat().st_size > 10_000
    assert cs.values.shape[2] == 7 and cs.y0 == pytest.approx(0.0) and cs.cell_m == 0.1  # 0..0.6 m
    assert np.isfinite(cs.values).all()  # 0.2 m between lines, gaps filled within two cells
    assert cs.depth_m[0] == pytest.approx(0.5 * 299792458.0 / np.sqrt(12) * 5e-9)
    # two perpendicular sets in one call: the last two lines as cross lines along y at x = 1 and 3 m
    assert main([*map(str, ["grid", *real_lines[:2], "--cross", *real_lines[2:], "--spacing", "0.2",
                            "--cross-spacing", "2", "--cross-origin", "1", "--out", tmp_path / "gx.h5"])]) == 0
    gx = Survey.load(tmp_path / "gx.h5")
    first = gx.metadata["grid"]["first_trace"]
    np.testing.assert_allclose(gx.positions_xyz[first[2]:first[3], 0], 1.0)
    np.testing.assert_allclose(gx.positions_xyz[first[3]:, 0], 3.0)
    assert gx.positions_xyz[first[3]:, 1].min() == pytest.approx(0.0, abs=1e-9)
    assert "2 + 2 perpendicular lines" in capsys.readouterr().out
    # pseudo-3D and 3D from the same lines: the same kind of output folder
    for method in ("pseudo3d", "backprojection"):
        assert main(["reconstruct", str(tmp_path / "g.h5"), "--method", method, "--eps-r", "12", "--spacing", "0.1",
                     "--max-depth", "2", "--min-depth", "0.42", "--no-time-zero", "--out", str(tmp_path / method)]) == 0
        out = capsys.readouterr().out
        assert ("line by line (pseudo-3D)" in out) == (method == "pseudo3d")
        cfg = json.loads((tmp_path / method / "config.json").read_text())
        assert cfg["config"]["method"] == method and cfg["frame"] is None
        assert (tmp_path / method / "top.png").stat().st_size > 10_000


@pytest.mark.parametrize("extra, words", [
    ([], "give --spacing"),
    (["--spacing", "0.2", "--layout", "x.txt"], "give --spacing"),
    (["--spacing", "-1"], "--spacing must be a positive distance"),
    (["--spacing", "0.2", "--reversed", "a,b"], "--reversed must be a comma-separated list of whole numbers"),
    (["--spacing", "0.2", "--reversed", "9"], "reversed lines must be line indices 0..3"),
    (["--spacing", "0.2", "--cross-spacing", "0", "--cross", "x.DT1"], "--cross-spacing must be a positive"),
    (["--layout", "x.txt", "--cross", "x.DT1"], "--cross goes with --spacing"),
])
def test_bad_grid_arguments_are_one_line(real_lines, tmp_path, capsys, extra, words):
    rc = main([*map(str, ["grid", *real_lines, "--out", tmp_path / "g.h5", *extra])])
    err = capsys.readouterr().err
    assert rc == 1 and words in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "g.h5").exists()
