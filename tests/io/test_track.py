import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.cli.main import main
from gpr3d.core.errors import FormatError
from gpr3d.io.trajectory import apply_track, read_track


def line_survey(n=41, step=0.05):
    return Survey(data=np.zeros((n, 32), np.float32), dt_s=1e-10,
                  positions_xyz=np.c_[np.arange(n) * step, np.zeros(n), np.zeros(n)])


def test_an_l_shaped_csv_track_places_the_traces_by_distance(tmp_path):
    (tmp_path / "t.csv").write_text("name,x,y,z\na,10,20,5\nb,11,20,5.1\nc,11,21,5.2\n")
    kind, pts = read_track(tmp_path / "t.csv")
    assert kind == "points" and pts.shape == (3, 3)
    s = apply_track(line_survey(), (kind, pts))  # 2 m of line on a 2 m track
    np.testing.assert_allclose(s.positions_xyz[20], [11, 20, 5.1], atol=1e-9)  # 1 m along: the corner
    np.testing.assert_allclose(s.positions_xyz[30], [11, 20.5, 5.15], atol=1e-9)
    (tmp_path / "bad.csv").write_text("x,y\n1,2\n")
    with pytest.raises(FormatError, match="lacks a z column"):
        read_track(tmp_path / "bad.csv")


def test_process_with_a_track_and_topographic_correction(tmp_path, capsys):
    line_survey().replace(eps_r=9.0).save(tmp_path / "line.h5")
    (tmp_path / "track.xyz").write_text("0 0 0.0\n2 0 0.3\n")
    assert main(["process", str(tmp_path / "line.h5"), "--track", str(tmp_path / "track.xyz"), "--steps",
                 "topo_correct", "--out", str(tmp_path / "out.h5")]) == 0
    out = Survey.load(tmp_path / "out.h5")
    assert out.positions_xyz[-1, 2] == pytest.approx(0.3)
    assert out.history[-1]["result"]["datum_elevation_m"] == pytest.approx(0.3)
    assert out.n_samples > 32
    capsys.readouterr()


def test_a_dzg_places_the_traces_on_their_gps_fixes(tmp_path):
    """GPS fixes tagged with their scan (trace) number: traces between fixes are interpolated; 0.001 minute of
    latitude is 1.853 m north."""
    lines = []
    for scan, lat_min in ((0, 39.2552), (100, 39.2562), (200, 39.2572)):
        lines += [f"$GSSIS,{scan},-1", f"$GPGGA,000320,47{lat_min:.4f},N,12218.5815,W,1,08,1.0,12.0,M,,M,,*00", ""]
    (tmp_path / "g.DZG").write_text("\n".join(lines))
    kind, (scans, pos) = read_track(tmp_path / "g.DZG")
    assert kind == "per_trace" and list(scans) == [0, 100, 200]
    placed = apply_track(line_survey(n=201), (kind, (scans, pos)))
    north = placed.positions_xyz[:, 1] - placed.positions_xyz[0, 1]
    assert north[100] == pytest.approx(1.853, rel=0.01) and north[50] == pytest.approx(north[100] / 2, rel=1e-6)
    assert abs(placed.positions_xyz[:, 0] - placed.positions_xyz[0, 0]).max() < 1e-6  # due north


def test_a_dzg_without_fixes_is_one_line():
    """The real SIR-4000 file's DZG logs GGA sentences with fix quality 0 (no fix): refused, naming the file."""
    from tests.conftest import real_file

    try:
        dzg = real_file("impdar_gssi_sir4000/test_gssi.DZG")
    except Exception:  # noqa: BLE001
        pytest.skip("../shared/data/real is absent")
    with pytest.raises(FormatError, match="test_gssi.DZG: holds 0 GPS fix"):
        read_track(dzg)
