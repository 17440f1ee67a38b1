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


# ---------------------------------------------------------------- the layout on disk, C-scans and profiles

from types import SimpleNamespace  # noqa: E402

from gpr3d import __version__  # noqa: E402
from gpr3d.io.volume import AXES, SCHEMA_VERSION, read_cscan, write_cscan, write_profile  # noqa: E402


def test_the_volume_layout_on_disk(tmp_path):
    vols = volumes()
    vols["image"] = vols["image"].astype(np.float64)  # float64 given: float32 stored
    p = write_volume(tmp_path / "v.h5", GRID, vols, eps_r=7.5, skipped=None)
    assert p == tmp_path / "v.h5"
    with h5py.File(p) as f:
        assert (f.attrs["schema"], int(f.attrs["schema_version"]), f.attrs["gpr3d_version"]) == \
            ("gpr3d.volume", 1, __version__)
        assert json.loads(f.attrs["grid_json"]) == GRID.to_dict() and f.attrs["axes"] == AXES
        assert "skipped" not in f.attrs  # None attributes left out
        d = f["image"]  # float32, contiguous and uncompressed (written in a fifth of gzip's time)
        assert d.dtype == np.float32 and d.compression is None and d.chunks is None and not d.shuffle
        np.testing.assert_array_equal(d[()], vols["image"].astype(np.float32))
    assert (SCHEMA, SCHEMA_VERSION, AXES) == ("gpr3d.volume", 1, "x, y, depth (positive down), metres")


def test_an_older_volume_and_bytes_attributes_are_read(tmp_path):
    p = tmp_path / "v.h5"
    write_volume(p, GRID, volumes())
    _edit(p, lambda f: (f.attrs.__delitem__("schema_version"), f.attrs.__setitem__("source", np.bytes_(b"x.DZT"))))
    v = read_volume(p)
    assert v.attrs["source"] == "x.DZT" and "grid_json" not in v.attrs
    _edit(p, lambda f: f.attrs.__setitem__("schema", np.bytes_(b"gpr3d.volume")))  # schema as bytes
    assert read_volume(p).grid == GRID


def _cscan(depth=True, eps=True):
    rng = np.random.default_rng(2)
    return SimpleNamespace(values=rng.uniform(0, 1, (3, 4, 5)).astype(np.float32), x0=1.25, y0=-0.5, cell_m=0.1,
                           window_s=2e-9, t_start_s=np.array([0.0, 2e-9, 4e-9]),
                           depth_m=np.array([0.0, 0.1, 0.2]) if depth else None, eps_r=9.0 if eps else None)


def test_a_cscan_round_trip_and_its_file(tmp_path):
    cs = _cscan()
    p = write_cscan(tmp_path / "c.h5", cs)
    with h5py.File(p) as f:
        assert f.attrs["schema"] == "gpr3d.cscan" and int(f.attrs["schema_version"]) == 1
        assert (f.attrs["x0"], f.attrs["y0"], f.attrs["cell_m"], f.attrs["window_s"], f.attrs["eps_r"]) == \
            (1.25, -0.5, 0.1, 2e-9, 9.0)
        assert f["values"].dtype == np.float32 and f["values"].compression == "gzip"
    back = read_cscan(p)
    np.testing.assert_array_equal(back.values, cs.values)
    np.testing.assert_array_equal(back.t_start_s, cs.t_start_s)
    np.testing.assert_array_equal(back.depth_m, cs.depth_m)
    assert (back.x0, back.y0, back.cell_m, back.window_s, back.eps_r) == (1.25, -0.5, 0.1, 2e-9, 9.0)
    plain = read_cscan(write_cscan(tmp_path / "d.h5", _cscan(depth=False, eps=False)))
    assert plain.depth_m is None and plain.eps_r is None
    with h5py.File(tmp_path / "d.h5") as f:
        assert "eps_r" not in f.attrs and "depth_m" not in f


def test_bad_cscan_files_are_named(tmp_path):
    p = tmp_path / "v.h5"
    write_volume(p, GRID, volumes())
    with pytest.raises(FormatError, match="^v.h5: is not a gpr3d C-scan file$"):
        read_cscan(p)
    c = write_cscan(tmp_path / "c.h5", _cscan())
    _edit(c, lambda f: f.__delitem__("values"))
    with pytest.raises(FormatError, match=r"^c.h5: unreadable C-scan \("):
        read_cscan(c)
    c = write_cscan(tmp_path / "c.h5", _cscan())
    _edit(c, lambda f: f.attrs.__delitem__("cell_m"))
    with pytest.raises(FormatError, match=r"^c.h5: unreadable C-scan \("):
        read_cscan(c)


def test_a_profile_file(tmp_path):
    prof = SimpleNamespace(image=np.arange(12.0).reshape(4, 3), along_m=np.array([0, 0.1, 0.2, 0.3]),
                           depth_m=np.array([0.0, 0.05, 0.1]), method="kirchhoff", eps_r=6.0)
    p = write_profile(tmp_path / "p.h5", prof)
    with h5py.File(p) as f:
        assert (f.attrs["schema"], int(f.attrs["schema_version"]), f.attrs["gpr3d_version"]) == \
            ("gpr3d.profile", 1, __version__)
        assert (f.attrs["method"], f.attrs["eps_r"], f.attrs["axes"]) == ("kirchhoff", 6.0, "along (m), depth (m, down)")
        np.testing.assert_array_equal(f["image"][()], prof.image)
        assert f["image"].dtype == np.float32 and f["image"].compression == "gzip"
        np.testing.assert_array_equal(f["along_m"][()], prof.along_m)
        np.testing.assert_array_equal(f["depth_m"][()], prof.depth_m)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["p.h5"]


def _stored(d, dtype):
    return d.dtype == dtype and d.compression == "gzip" and d.compression_opts == 4 and d.shuffle


def test_every_dataset_is_stored_alike(tmp_path):
    """Volumes, C-scan values and profile images as float32, their axes as float64, all gzip 4 with shuffle (the
    one helper every writer here uses)."""
    from gpr3d.io.volume import _store

    with h5py.File(tmp_path / "s.h5", "w") as f:
        _store(f, "a", [1, 2, 3])
        _store(f, "b", [1, 2, 3], np.float64)
        assert _stored(f["a"], np.float32) and _stored(f["b"], np.float64)
        np.testing.assert_array_equal(f["b"][()], [1.0, 2.0, 3.0])
    c = write_cscan(tmp_path / "c.h5", _cscan())
    with h5py.File(c) as f:
        assert _stored(f["values"], np.float32) and _stored(f["t_start_s"], np.float64)
        assert _stored(f["depth_m"], np.float64)
        assert f.attrs["gpr3d_version"] == __version__
        assert f.attrs["axes"] == "slice, x (east), y (north); cell centres x0 + i * cell_m"
    prof = SimpleNamespace(image=np.ones((2, 3)), along_m=[0, 1], depth_m=[0, 1, 2], method="stolt", eps_r=4.0)
    with h5py.File(write_profile(tmp_path / "p.h5", prof)) as f:
        assert _stored(f["image"], np.float32) and _stored(f["along_m"], np.float64)
        assert _stored(f["depth_m"], np.float64)


def test_read_volume_messages_and_values(tmp_path):
    p = tmp_path / "v.h5"
    write_volume(p, GRID, volumes(), note=np.float64(2.5))
    v = read_volume(p)
    assert v.arrays["image"].dtype == np.float32 and type(v.attrs["note"]) is float
    with pytest.raises(FormatError) as e:
        read_volume(p, names=["fold"])
    assert str(e.value) == "v.h5: holds no volume 'fold' (it has envelope, image)"
    for damage, start in ((lambda f: f.attrs.__setitem__("schema", "x"), "v.h5: not a gpr3d volume"),
                          (lambda f: f.attrs.__setitem__("schema_version", 9), "v.h5: gpr3d.volume schema version 9"),
                          (lambda f: f.attrs.__setitem__("grid_json", "{"), "v.h5: its grid_json attribute is not a grid "
                                                                           "(Expecting property name"),
                          (lambda f: f["image"].__setitem__((0, 0, 0), np.inf), "v.h5: volume 'image' holds NaN"),
                          (lambda f: (f.__delitem__("image"), f.create_dataset("image", data=np.zeros((1, 1, 1)))),
                           "v.h5: volume 'image' is (1, 1, 1)")):
        write_volume(p, GRID, volumes())
        _edit(p, damage)
        with pytest.raises(FormatError) as e:
            read_volume(p)
        assert str(e.value).startswith(start), str(e.value)
    import h5py as _h

    with _h.File(tmp_path / "empty.h5", "w") as f:
        f.attrs.update({"schema": SCHEMA, "schema_version": 1, "grid_json": json.dumps(GRID.to_dict())})
    with pytest.raises(FormatError, match=r"holds no volume 'image' \(it has none\)$"):
        read_volume(tmp_path / "empty.h5", names=["image"])


def test_the_vti_spacing_is_the_grid_s(tmp_path):
    write_vti(tmp_path / "v.vti", GRID, {"envelope": volumes()["envelope"], "none": None})
    head = (tmp_path / "v.vti").read_bytes()
    head = head[: head.index(b"<AppendedData")].decode()
    spacing = [float(v) for v in head.split('Spacing="')[1].split('"')[0].split()]
    np.testing.assert_allclose(spacing, [GRID.dx, GRID.dy, GRID.dd])
    assert 'Name="none"' not in head and 'Name="envelope"' in head
    assert sorted(x.name for x in tmp_path.iterdir()) == ["v.vti"]


def test_the_vti_holds_every_volume_at_its_offset(tmp_path):
    """Each DataArray's offset (counted from the byte after the '_' that opens the appended block) leads to an
    8-byte little-endian byte count and then that volume's values, x fastest and depth reversed (z up)."""
    import xml.etree.ElementTree as ET

    vols = volumes()
    vols["image"] = vols["image"].astype(np.float64)  # float64 given: float32 written
    write_vti(tmp_path / "v.vti", GRID, {"envelope": vols["envelope"], "skipped": None, "image": vols["image"]})
    raw = (tmp_path / "v.vti").read_bytes()
    head = raw[: raw.index(b"<AppendedData")].decode()
    root = ET.fromstring(head + "</VTKFile>")
    pd = root.find("ImageData/Piece/PointData")
    assert pd.get("Scalars") == "envelope" and [e.get("Name") for e in pd] == ["envelope", "image"]
    assert all(not (e.tail or "").strip() for e in pd) and not (pd.text or "").strip()
    start = raw.index(b"_", raw.index(b"<AppendedData")) + 1
    n = int(np.prod(GRID.shape))
    for name in ("envelope", "image"):
        tag = head.split(f'Name="{name}"')[1].split("/>")[0]
        assert 'type="Float32"' in tag and 'format="appended"' in tag
        at = start + int(tag.split('offset="')[1].split('"')[0])
        assert int(np.frombuffer(raw[at: at + 8], "<u8")[0]) == 4 * n
        vals = np.frombuffer(raw[at + 8: at + 8 + 4 * n], "<f4")
        np.testing.assert_array_equal(vals, vols[name][:, :, ::-1].ravel(order="F").astype(np.float32))
    assert raw.endswith(b"</AppendedData>\n</VTKFile>\n")
    extent = head.split('WholeExtent="')[1].split('"')[0]
    assert extent == f"0 {GRID.nx - 1} 0 {GRID.ny - 1} 0 {GRID.nd - 1}"


def test_a_vti_volume_off_the_grid_is_refused(tmp_path):
    env = volumes()["envelope"]
    with pytest.raises(ValueError, match=r"volume 'envelope' has shape .* the grid"):
        write_vti(tmp_path / "v.vti", GRID, {"envelope": env[:, :, :-1]})
    assert not list(tmp_path.iterdir())


def test_vtk_reads_the_vti_as_written(tmp_path):
    """VTK's own reader (ParaView's): the grid's extent, origin (deepest voxel, z up) and spacing, and each volume
    back with depth reversed. Skipped where the vtk package is not installed (it is not a gpr3d dependency)."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    vols = volumes(3)
    write_vti(tmp_path / "v.vti", GRID, {"envelope": vols["envelope"], "noise_map": vols["image"]})
    r = vtk.vtkXMLImageDataReader()
    r.SetFileName(str(tmp_path / "v.vti"))
    r.Update()
    im = r.GetOutput()
    assert im.GetDimensions() == GRID.shape
    np.testing.assert_allclose(im.GetOrigin(), [GRID.x0, GRID.y0, -(GRID.d0 + (GRID.nd - 1) * GRID.dd)])
    np.testing.assert_allclose(im.GetSpacing(), [GRID.dx, GRID.dy, GRID.dd])
    for name, ref in (("envelope", vols["envelope"]), ("noise_map", vols["image"])):
        v = vtk_to_numpy(im.GetPointData().GetArray(name)).reshape(GRID.nd, GRID.ny, GRID.nx).transpose(2, 1, 0)
        np.testing.assert_array_equal(v[:, :, ::-1], ref)


def test_a_vti_of_no_volume_is_an_empty_image(tmp_path):
    import xml.etree.ElementTree as ET

    write_vti(tmp_path / "v.vti", GRID, {"envelope": None})
    raw = (tmp_path / "v.vti").read_bytes()
    root = ET.fromstring(raw[: raw.index(b"<AppendedData")].decode() + "</VTKFile>")
    pd = root.find("ImageData/Piece/PointData")
    assert pd is not None and len(pd) == 0 and pd.get("Scalars") is None
    assert raw.endswith(b'<AppendedData encoding="raw">\n_\n</AppendedData>\n</VTKFile>\n')
