"""gpr3d.volume files: what is written reads back exactly; a file that is not one, or is damaged, is named."""

import json

import h5py
import numpy as np
import pytest

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.io.volume import SCHEMA, read_volume, write_volume, write_vti

GRID = Grid3D(1.5, -2.0, 0.05, 0.02, 0.03, 0.01, 6, 5, 7)


def volumes(seed=0):
    rng = np.random.default_rng(seed)
    return {"image": rng.standard_normal(GRID.shape).astype(np.float32),
            "envelope": rng.uniform(0, 3, GRID.shape).astype(np.float32)}


def test_a_volume_reads_back_exactly(tmp_path):
    arrays = volumes()
    write_volume(tmp_path / "v.h5", GRID, {**arrays, "noise_map": None}, eps_r=7.5, source="line.DZT")
    v = read_volume(tmp_path / "v.h5")
    assert v.grid == GRID
    assert sorted(v.arrays) == ["envelope", "image"]  # None left out
    for k, a in arrays.items():
        np.testing.assert_array_equal(v.arrays[k], a)
    assert v.attrs["schema"] == SCHEMA and v.attrs["eps_r"] == 7.5 and v.attrs["source"] == "line.DZT"
    only = read_volume(tmp_path / "v.h5", names=["envelope"])
    assert list(only.arrays) == ["envelope"]
    with pytest.raises(FormatError, match="holds no volume 'fold'"):
        read_volume(tmp_path / "v.h5", names=["fold"])


def test_writing_a_volume_of_another_shape_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"volume 'image' is \(6, 5, 6\)"):
        write_volume(tmp_path / "v.h5", GRID, {"image": np.zeros((6, 5, 6), np.float32)})
    assert not (tmp_path / "v.h5").exists()


def _edit(path, fn):
    with h5py.File(path, "r+") as f:
        fn(f)


@pytest.mark.parametrize("damage, words", [
    (lambda f: f.attrs.__setitem__("schema", "gpr3d.survey"), r"not a gpr3d volume \(schema attribute 'gpr3d.survey'"),
    (lambda f: f.attrs.__setitem__("schema_version", 9), "schema version 9 is newer"),
    (lambda f: f.attrs.__setitem__("grid_json", "{\"nx\": 3}"), "its grid_json attribute is not a grid"),
    (lambda f: f.attrs.__setitem__("grid_json", json.dumps({**GRID.to_dict(), "dx": -0.02})),
     "its grid_json attribute is not a grid"),
    (lambda f: (f.__delitem__("image"), f.create_dataset("image", data=np.zeros((6, 5, 3), np.float32))),
     r"volume 'image' is \(6, 5, 3\), its grid is \(6, 5, 7\)"),
    (lambda f: f["image"].__setitem__((0, 0, 0), np.nan), "volume 'image' holds NaN"),
])
def test_damaged_volumes_are_named(tmp_path, damage, words):
    p = tmp_path / "v.h5"
    write_volume(p, GRID, volumes())
    _edit(p, damage)
    with pytest.raises(FormatError, match=words):
        read_volume(p)


def test_truncated_and_foreign_files_are_named(tmp_path):
    p = tmp_path / "v.h5"
    write_volume(p, GRID, volumes())
    cut = tmp_path / "cut.h5"
    cut.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    with pytest.raises(FormatError, match="cut.h5"):
        read_volume(cut)
    (tmp_path / "empty.h5").write_bytes(b"")
    with pytest.raises(FormatError, match="empty"):
        read_volume(tmp_path / "empty.h5")
    with pytest.raises(FormatError, match="no such file"):
        read_volume(tmp_path / "none.h5")


def test_grid_from_dict_checks_what_it_is_given():
    assert Grid3D.from_dict(GRID.to_dict()) == GRID
    for bad in ({"nx": 3}, {**GRID.to_dict(), "nd": 0}, {**GRID.to_dict(), "x0": float("nan")},
                {**GRID.to_dict(), "dy": "wide"}, [1, 2]):
        with pytest.raises(InvalidDataError):
            Grid3D.from_dict(bad)


def test_vti_holds_the_volume_depth_up(tmp_path):
    """The .vti's origin is the deepest voxel (z up) and its raw point data is the envelope with depth reversed."""
    pytest.importorskip("pyevtk")
    env = volumes()["envelope"]
    write_vti(tmp_path / "v.vti", GRID, {"envelope": env})
    raw = (tmp_path / "v.vti").read_bytes()
    head = raw[: raw.index(b"<AppendedData")].decode()
    z_bottom = -(GRID.d0 + (GRID.nd - 1) * GRID.dd)
    origin = head.split('Origin="')[1].split('"')[0].split()
    np.testing.assert_allclose([float(v) for v in origin], [GRID.x0, GRID.y0, z_bottom])
    # appended raw data: '_' then a 4- or 8-byte size header, then x-fastest float32 values
    body = raw[raw.index(b"_", raw.index(b"<AppendedData")) + 1:]
    n = env.size * 4
    for hdr in (4, 8):
        vals = np.frombuffer(body[hdr: hdr + n], np.float32)
        if vals.size == env.size and np.array_equal(vals, env[:, :, ::-1].ravel(order="F")):
            break
    else:
        pytest.fail("the .vti's point data is not the envelope with depth reversed")
