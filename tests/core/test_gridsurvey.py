import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.gridsurvey import assemble_grid, read_layout


def line(n, step=0.05, samples=16, seed=0, name="L.h5"):
    rng = np.random.default_rng(seed)
    pos = np.c_[np.arange(n) * step, np.zeros(n), np.zeros(n)]
    return Survey(data=rng.standard_normal((n, samples)).astype(np.float32), dt_s=1e-10, positions_xyz=pos,
                  offset_m=0.1, metadata={"path": name})


def test_parallel_lines_land_on_their_rows_with_headings_along_them():
    lines = [line(11, seed=k, name=f"L{k}.h5") for k in range(3)]
    g = assemble_grid(lines, line_spacing_m=0.2)
    assert g.n_traces == 33
    np.testing.assert_allclose(g.positions_xyz[11:22, 1], 0.2)
    np.testing.assert_allclose(g.positions_xyz[22:, 0], np.arange(11) * 0.05, atol=1e-12)
    np.testing.assert_array_equal(g.data[11:22], lines[1].data)
    assert g.metadata["grid"]["first_trace"] == [0, 11, 22]
    np.testing.assert_allclose(g.orientations_quat_wxyz[:, 0], 1.0)  # heading +x: the identity rotation


def test_serpentine_reversed_offsets_and_lines_along_y():
    lines = [line(11, seed=k) for k in range(3)]
    g = assemble_grid(lines, line_spacing_m=0.5, serpentine=True, start_offsets_m=[0.0, 0.1, 0.0])
    # line 1 was walked back: its first trace at the far end (0.1 + 0.5 m), its last at its start
    assert g.positions_xyz[11, 0] == pytest.approx(0.6) and g.positions_xyz[21, 0] == pytest.approx(0.1)
    np.testing.assert_allclose(g.positions_xyz[22:, 0], np.arange(11) * 0.05, atol=1e-12)
    g2 = assemble_grid(lines, line_spacing_m=0.5, direction="y", reversed_lines=[0])
    assert g2.positions_xyz[0, 1] == pytest.approx(0.5) and g2.positions_xyz[10, 1] == pytest.approx(0.0)
    np.testing.assert_allclose(g2.positions_xyz[11:22, 0], 0.5)


def test_a_layout_file_places_each_line_by_its_ends(tmp_path):
    (tmp_path / "lines.txt").write_text("# name x0 y0 x1 y1\nA.h5 1 1 1 2\nB.h5, 2, 2, 1, 2\n")
    layout = read_layout(tmp_path / "lines.txt")
    g = assemble_grid([line(11, name="A.h5"), line(11, name="B.h5")], layout=layout)
    np.testing.assert_allclose(g.positions_xyz[:11, :2], np.c_[np.ones(11), 1 + np.arange(11) * 0.05], atol=1e-12)
    np.testing.assert_allclose(g.positions_xyz[11:, :2], np.c_[2 - np.arange(11) * 0.05, 2 * np.ones(11)], atol=1e-12)
    with pytest.raises(InvalidDataError, match="no entry for C.h5"):
        assemble_grid([line(5, name="A.h5"), line(5, name="C.h5")], layout=layout)
    (tmp_path / "bad.txt").write_text("A.h5 1 1 one 2\n")
    with pytest.raises(InvalidDataError, match="bad.txt line 1: coordinates must be numbers"):
        read_layout(tmp_path / "bad.txt")


def test_lines_that_do_not_match_are_refused():
    with pytest.raises(InvalidDataError, match="lines of one grid must match"):
        assemble_grid([line(5), line(5).replace(dt_s=2e-10)], line_spacing_m=0.2)
    with pytest.raises(InvalidDataError, match="correct time zero line by line"):
        assemble_grid([line(5), line(5).replace(t0_s=1e-9)], line_spacing_m=0.2)
    # records cut to different lengths by time zero: the common length is kept
    g = assemble_grid([line(5), line(5, samples=20)], line_spacing_m=0.2)
    assert g.n_samples == 16 and g.metadata["grid"]["samples_kept"] == 16
    with pytest.raises(InvalidDataError, match="spacing or a layout"):
        assemble_grid([line(5), line(5)])
    with pytest.raises(InvalidDataError, match="line spacing must be a positive"):
        assemble_grid([line(5), line(5)], line_spacing_m=-1.0)
    with pytest.raises(InvalidDataError, match="reversed lines must be line indices"):
        assemble_grid([line(5), line(5)], line_spacing_m=0.2, reversed_lines=[2])


def test_a_perpendicular_set_lies_across_the_first():
    """3 lines along x at y = 0, 0.5, 1.0 and 2 cross lines along y at x = 0.2 + 0.4 j, the second walked back."""
    main = [line(21, seed=k, name=f"X{k}.h5") for k in range(3)]  # 1 m long
    cross = [line(25, seed=10 + k, name=f"Y{k}.h5") for k in range(2)]  # 1.2 m long
    g = assemble_grid(main + cross, line_spacing_m=0.5, cross_lines=2, cross_spacing_m=0.4, cross_origin_m=0.2,
                      reversed_lines=[4])
    assert g.n_traces == 3 * 21 + 2 * 25
    np.testing.assert_allclose(g.positions_xyz[21:42, 1], 0.5)
    y0, y1 = g.positions_xyz[63:88], g.positions_xyz[88:]
    np.testing.assert_allclose(y0[:, 0], 0.2)
    np.testing.assert_allclose(y0[:, 1], np.arange(25) * 0.05, atol=1e-12)
    np.testing.assert_allclose(y1[:, 0], 0.6)
    np.testing.assert_allclose(y1[:, 1], 1.2 - np.arange(25) * 0.05, atol=1e-12)  # walked back from y = 1.2
    np.testing.assert_array_equal(g.data[88:], cross[1].data)
    # headings: +y on the first cross line (yaw 90 deg: w = cos 45 deg), -y on the reversed one
    np.testing.assert_allclose(g.orientations_quat_wxyz[63, [0, 3]], [np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(abs(g.orientations_quat_wxyz[88, 0]), np.sqrt(0.5), atol=1e-12)
    assert g.orientations_quat_wxyz[88, 0] * g.orientations_quat_wxyz[88, 3] < 0
    for bad, words in (({"cross_lines": 5}, "0..4"), ({"cross_lines": 2, "cross_spacing_m": 0.0}, "cross lines' spacing"),
                       ({"cross_lines": 2, "cross_origin_m": float("nan")}, "origin")):
        with pytest.raises(InvalidDataError, match=words):
            assemble_grid(main + cross, line_spacing_m=0.5, **bad)


def test_marks_spread_the_traces_between_known_distances():
    """Marks at traces 10, 30 and 70, one every 2 m from 1 m: 20 traces to the first 2 m, 40 to the next; before the
    first and after the last mark the nearest interval's rate."""
    from gpr3d.core.gridsurvey import marks_distance, place_by_marks

    d = marks_distance(81, [10, 30, 70], 2.0, start_m=1.0)
    assert d[[10, 30, 70]] == pytest.approx([1.0, 3.0, 5.0])
    assert d[20] == pytest.approx(2.0) and d[50] == pytest.approx(4.0)
    assert d[0] == pytest.approx(1.0 - 10 * 0.1) and d[80] == pytest.approx(5.0 + 10 * 0.05)
    s = place_by_marks(line(81), 2.0, marks=[10, 30, 70])
    np.testing.assert_allclose(s.positions_xyz[:, 0], marks_distance(81, [10, 30, 70], 2.0))
    np.testing.assert_allclose(s.positions_xyz[:, 1:], 0.0)
    for marks, spacing, words in (([5], 1.0, "at least two"), ([5, 3], 1.0, "increasing"), ([0, 81], 1.0, "0..80"),
                                  ([0, 5], 0.0, "positive")):
        with pytest.raises(InvalidDataError, match=words):
            marks_distance(81, marks, spacing)
    with pytest.raises(InvalidDataError, match="holds 0 mark"):
        place_by_marks(line(81), 1.0)
