import numpy as np
import pytest

import gpr3d
from gpr3d.io.segy import write_segy
from tests.conftest import real_file

segyio = pytest.importorskip("segyio")


def test_segy_round_trip_through_segyio(tmp_path):
    s = gpr3d.read(real_file("gprpy_sns_50MHz/XLINE00.DT1"))
    out = tmp_path / "x.sgy"
    write_segy(s, out)
    with segyio.open(out, ignore_geometry=True) as f:
        assert f.tracecount == s.n_traces
        assert f.bin[segyio.BinField.Interval] == 800  # ps
        np.testing.assert_array_equal(segyio.tools.collect(f.trace[:]), s.data)
        h = f.header[10]
        assert h[segyio.TraceField.SourceX] == round(s.positions_xyz[10, 0] * 1000)
        assert h[segyio.TraceField.SourceGroupScalar] == -1000
        assert b"PICOSECONDS" in f.text[0]


def test_segy_rejects_huge_interval(tmp_path):
    s = gpr3d.Survey(data=np.zeros((2, 4)), dt_s=1e-7)
    with pytest.raises(gpr3d.InvalidDataError, match="16-bit"):
        write_segy(s, tmp_path / "y.sgy")
    assert not (tmp_path / "y.sgy").exists()
