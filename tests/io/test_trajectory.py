import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.core.poses import quat_from_yaw
from gpr3d.io.trajectory import Trajectory, attach_poses, read_csv_trajectory, read_trajectory, read_tum, write_tum


def test_tum_round_trip_and_quaternion_order(tmp_path):
    p = tmp_path / "t.txt"
    # TUM: t tx ty tz qx qy qz qw ; a 90 degree yaw is qz = qw = sqrt(1/2)
    p.write_text("# comment\n0.0 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n1.0 4 5 6 0 0 0 1\n")
    tr = read_tum(p)
    np.testing.assert_allclose(tr.orientations_quat_wxyz[0], [0.7071067811865476, 0, 0, 0.7071067811865476])
    write_tum(tr, tmp_path / "u.txt")
    back = read_trajectory(tmp_path / "u.txt")
    np.testing.assert_array_equal(back.positions_xyz, tr.positions_xyz)
    np.testing.assert_allclose(back.orientations_quat_wxyz, tr.orientations_quat_wxyz, atol=1e-15)


def test_csv(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("time,x,y,z,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n0.5,1,0,0,1,0,0,0\n")
    tr = read_csv_trajectory(p)
    assert len(tr) == 2 and tr.positions_xyz[1, 0] == 1
    (tmp_path / "n.csv").write_text("a,b\n1,2\n")
    with pytest.raises(FormatError, match="lacks column"):
        read_csv_trajectory(tmp_path / "n.csv")


def test_attach_by_index_and_time():
    s = Survey(data=np.zeros((3, 8)), dt_s=1e-10, timestamps_s=[0.25, 0.5, 1.5])
    tr = Trajectory([0.0, 1.0, 2.0], [[0, 0, 0], [2, 0, 0], [2, 2, 0]], quat_from_yaw([0, np.pi / 2, np.pi / 2]))
    by_i = attach_poses(s, tr)
    np.testing.assert_array_equal(by_i.positions_xyz, tr.positions_xyz)
    by_t = attach_poses(s, tr, by="time")
    np.testing.assert_allclose(by_t.positions_xyz, [[0.5, 0, 0], [1, 0, 0], [2, 1, 0]])
    np.testing.assert_allclose(by_t.headings_rad, [np.pi / 8, np.pi / 4, np.pi / 2])
    with pytest.raises(InvalidDataError, match="outside the trajectory"):
        attach_poses(s.replace(timestamps_s=[0, 1, 3.0]), tr, by="time")
    with pytest.raises(InvalidDataError, match="2 poses but the survey has 3"):
        attach_poses(s, Trajectory([0, 1], [[0, 0, 0]] * 2, [[1, 0, 0, 0]] * 2))


# ---------------------------------------------------------------- the readers and writers value by value

import math  # noqa: E402

from gpr3d.io.trajectory import apply_track, attach_track, read_track, read_xyz_track  # noqa: E402


def test_tum_lines_comments_separators_and_quaternion_order(tmp_path):
    p = tmp_path / "a.tum"
    p.write_text("# t tx ty tz qx qy qz qw\n\n   \n0.5,1.5,-2,3e-1,0.1,0.2,0.3,0.9\n  # indented comment\n"
                 "0.5 7 8 9 0 0 0 2\n")  # equal times pass (a cart at rest)
    tr = read_tum(p)
    np.testing.assert_array_equal(tr.timestamps_s, [0.5, 0.5])
    np.testing.assert_array_equal(tr.positions_xyz, [[1.5, -2, 0.3], [7, 8, 9]])
    q = tr.orientations_quat_wxyz
    np.testing.assert_allclose(q[0], np.array([0.9, 0.1, 0.2, 0.3]) / math.sqrt(0.95))  # w first, made unit
    np.testing.assert_allclose(q[1], [1, 0, 0, 0])


@pytest.mark.parametrize("name, text, msg", [
    ("bad.txt", "0 1 2 3 0 0 0 1\n1 1 2 3 0 0 0\n", "bad.txt: line 2: expected 8 numbers (t tx ty tz qx qy qz qw), got 7"),
    ("bad.txt", "# c\n\n0 1 2 3 0 0 0 1 9\n", "bad.txt: line 3: expected 8 numbers (t tx ty tz qx qy qz qw), got 9"),
    ("bad.txt", "0 1 2 3 0 0 0 1\n0 1 2 x 0 0 0 1\n", "bad.txt: line 2: not a number in '0 1 2 x 0 0 0 1'"),
    ("bad.txt", "0 inf 2 3 0 0 0 1\n", "bad.txt: holds NaN/inf values"),
    ("bad.txt", "0 1 2 3 0 0 0 1e-10\n", "bad.txt: holds a zero quaternion"),
    ("bad.txt", "0 1 2 3 0 0 0 1\n2 1 2 3 0 0 0 1\n1.5 1 2 3 0 0 0 1\n",
     "bad.txt: timestamps run backwards at pose 2 (1.5 s after 2.0 s)"),
    ("bad.txt", "", "bad.txt: file is empty"),
    ("bad.txt", "# nothing but a comment\n\n", "bad.txt: holds no poses"),
    ("c.csv", "", "c.csv: file is empty"),
    ("c.csv", "\n", "c.csv: CSV header lacks column(s) ['t', 'x', 'y', 'z'] (has [])"),
    ("c.csv", "t,x,y\n0,1,2\n", "c.csv: CSV header lacks column(s) ['z'] (has ['t', 'x', 'y'])"),
    ("c.csv", "t,x,y,z\n", "c.csv: holds no poses"),
    ("c.csv", "t,x,y,z\n0,1,2,3\n1,1,two,3\n", "c.csv: line 3: bad or missing number"),
    ("c.csv", "t,x,y,z\n0,1,2,3\n1,1,2\n", "c.csv: line 3: bad or missing number"),
    ("c.csv", "t,x,y,z\n0,1,2,nan\n", "c.csv: holds NaN/inf values"),
    ("c.csv", "t,x,y,z\n1,1,2,3\n0,1,2,3\n", "c.csv: timestamps run backwards at pose 1 (0.0 s after 1.0 s)"),
])
def test_bad_trajectory_files_are_named(tmp_path, name, text, msg):
    """TUM (.txt) and CSV (.csv) files alike: one line naming the file and what is wrong."""
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(FormatError) as e:
        read_trajectory(p)
    assert str(e.value) == msg


def test_a_quaternion_just_above_zero_is_kept(tmp_path):
    p = tmp_path / "q.txt"
    p.write_text("0 1 2 3 0 0 0 1e-8\n")
    np.testing.assert_allclose(read_tum(p).orientations_quat_wxyz, [[1, 0, 0, 0]])


def test_write_tum_exactly(tmp_path):
    tr = Trajectory([0.1, 0.30000000000000004], [[1, 2, 3], [4.25, -5, 6e-7]],
                    [[0.5, 0.5, -0.5, 0.5], [1, 0, 0, 0]])
    p = tmp_path / "w.tum"
    write_tum(tr, p)
    lines = p.read_text().splitlines()
    assert lines[0] == "# t tx ty tz qx qy qz qw"
    assert lines[1] == "0.1 1.0 2.0 3.0 0.5 -0.5 0.5 0.5"
    assert lines[2] == "0.30000000000000004 4.25 -5.0 6e-07 0.0 0.0 0.0 1.0"
    assert len(lines) == 3 and not list(tmp_path.glob("*.part"))
    back = read_tum(p)
    np.testing.assert_array_equal(back.timestamps_s, tr.timestamps_s)
    np.testing.assert_array_equal(back.positions_xyz, tr.positions_xyz)


@pytest.mark.parametrize("head, t_scale", [("t,x,y,z", 1.0), ("timestamp, tx, ty, tz", 1.0),
                                          ("time_s,px,py,pz", 1.0), ("timestamp_s,x_m,y_m,z_m", 1.0)])
def test_csv_column_names_and_no_quaternion(tmp_path, head, t_scale):
    p = tmp_path / "c.csv"
    p.write_text(f"{head}\n0,1,2,3\n\n , , \n2.5,4,5,6\n")
    tr = read_csv_trajectory(p)
    np.testing.assert_array_equal(tr.timestamps_s, [0.0, 2.5 * t_scale])
    np.testing.assert_array_equal(tr.positions_xyz, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(tr.orientations_quat_wxyz, [[1, 0, 0, 0]] * 2)  # none given: identity


def test_csv_columns_in_any_order_with_others_beside(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("qz,z,note,qy,y,qx,x,w,time\n0,3,a,0,2,1,1,0,0.0\n0,6,b,0,5,0,4,1,1.0\n")
    tr = read_csv_trajectory(p)
    np.testing.assert_array_equal(tr.positions_xyz, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_allclose(tr.orientations_quat_wxyz, [[0, 1, 0, 0], [1, 0, 0, 0]])


def test_euroc_ground_truth(tmp_path):
    p = tmp_path / "data.csv"
    p.write_text("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n"
                 "1403636579758555392,4.68,-1.79,0.79,0.53,-0.15,-0.83,-0.08\n"
                 "1403636579763555584,4.69,-1.80,0.80,0.53,-0.15,-0.83,-0.08\n")
    tr = read_trajectory(p)
    assert tr.timestamps_s[1] - tr.timestamps_s[0] == pytest.approx(0.005, abs=1e-6)  # nanoseconds to seconds
    np.testing.assert_allclose(tr.positions_xyz[0], [4.68, -1.79, 0.79])


def test_read_trajectory_chooses_by_suffix(tmp_path):
    (tmp_path / "a.CSV").write_text("t,x,y,z\n0,1,2,3\n")
    assert read_trajectory(tmp_path / "a.CSV").positions_xyz.tolist() == [[1, 2, 3]]
    (tmp_path / "a.txt").write_text("0,1,2,3,0,0,0,1\n")  # commas in a TUM file are separators too
    assert read_trajectory(tmp_path / "a.txt").positions_xyz.tolist() == [[1, 2, 3]]


def test_xyz_tracks(tmp_path):
    p = tmp_path / "t.xyz"
    p.write_text("# surveyed\n0 0 1\n3,4,1.5\n")
    np.testing.assert_array_equal(read_xyz_track(p), [[0, 0, 1], [3, 4, 1.5]])
    p.write_text("0 0\n")
    with pytest.raises(FormatError, match=r"^t.xyz: line 1: expected 3 numbers \(x y z\), got 2$"):
        read_xyz_track(p)


def test_attach_by_index_takes_the_trajectory_times_and_says_so():
    s = Survey(data=np.zeros((2, 8)), dt_s=1e-10, timestamps_s=[5.0, 6.0])
    tr = Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]], quat_from_yaw([0.0, 0.5]))
    out = attach_poses(s, tr)
    np.testing.assert_array_equal(out.timestamps_s, [0.0, 1.0])
    np.testing.assert_allclose(out.orientations_quat_wxyz, tr.orientations_quat_wxyz)
    assert out.metadata["positions_source"] == "trajectory (index)"
    assert s.positions_xyz is None  # the input is left as it was


def test_attach_by_time_with_latency():
    s = Survey(data=np.zeros((2, 8)), dt_s=1e-10, timestamps_s=[0.5, 1.0])
    tr = Trajectory([0.0, 1.0, 2.0], [[0, 0, 0], [2, 0, 0], [4, 0, 0]], quat_from_yaw([0.0, 0.0, 0.0]))
    out = attach_poses(s, tr, by="time", latency_s=0.25)  # the radar's clock 0.25 s behind
    np.testing.assert_allclose(out.positions_xyz[:, 0], [1.5, 2.5])
    assert out.metadata["positions_source"] == "trajectory (time)"
    with pytest.raises(InvalidDataError, match="^by must be 'index' or 'time', got 'distance'$"):
        attach_poses(s, tr, by="distance")
    with pytest.raises(InvalidDataError, match="^survey has no timestamps to interpolate poses at$"):
        attach_poses(s.replace(timestamps_s=None), tr, by="time")


def test_attach_track_by_distance_heading_and_warning():
    # a survey whose first trace is at x = 2 m: distances count from it
    s = Survey(data=np.zeros((5, 8), np.float32), dt_s=1e-10,
               positions_xyz=np.c_[2 + np.arange(5) * 0.5, np.zeros(5), np.zeros(5)])
    track = np.array([[0, 0, 1], [1, 0, 1], [1, 0, 5], [1, 1, 2]], float)  # a repeated point (a vertical step)
    out = attach_track(s, track)
    np.testing.assert_allclose(out.positions_xyz[:, :2], [[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1]])
    np.testing.assert_allclose(out.positions_xyz[:, 2], [1, 1, 1, 1.5, 2])  # the repeated point dropped
    np.testing.assert_allclose(out.headings_rad, [0, 0, np.pi / 2, np.pi / 2, np.pi / 2])
    assert out.metadata["positions_source"] == "along-line distance placed on an xyz track"
    assert "track_warning" not in out.metadata
    long = s.replace(positions_xyz=np.c_[np.arange(5) * 0.53, np.zeros(5), np.zeros(5)])  # 2.12 m on 2 m: > 5 %
    assert attach_track(long, track).metadata["track_warning"] == \
        "survey line 2.12 m is longer than the track 2.00 m"
    fits = s.replace(positions_xyz=np.c_[np.arange(5) * 0.52, np.zeros(5), np.zeros(5)])  # 2.08 m: within 5 %
    assert "track_warning" not in attach_track(fits, track).metadata
    with pytest.raises(InvalidDataError, match="^track must be \\(n >= 2, 3\\) points$"):
        attach_track(s, track[:1])
    with pytest.raises(InvalidDataError, match="track must be"):
        attach_track(s, track[:, :2])
    with pytest.raises(InvalidDataError, match="^survey has no along-line positions to place on the track$"):
        attach_track(s.replace(positions_xyz=None), track)


def test_read_track_points_csv_names_and_errors(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("TX , Ty,tz,extra\n1,2,3,a\n\n4,5,6,b\n")
    kind, pts = read_track(p)
    assert kind == "points"
    np.testing.assert_array_equal(pts, [[1, 2, 3], [4, 5, 6]])
    for text, msg in (("", "t.csv: file is empty"), ("\n", "t.csv: CSV header lacks a x column (has [])"),
                      ("x,y,z\n1,2,3\n1,b,3\n", "t.csv: line 3: x, y, z must be numbers, got ['1', 'b', '3']"),
                      ("x,y,z\n1,2,3\n", "t.csv: a track needs two finite x y z points at least"),
                      ("x,y,z\n1,2,3\n1,nan,3\n", "t.csv: a track needs two finite x y z points at least")):
        p.write_text(text)
        with pytest.raises(FormatError) as e:
            read_track(p)
        assert str(e.value) == msg
    t = tmp_path / "t.txt"
    t.write_text("0 0 0\n")
    with pytest.raises(FormatError, match="^t.txt: a track needs two finite x y z points at least$"):
        read_track(t)
    t.write_text("0 0 0\n1 1 1\n")
    assert read_track(t)[0] == "points"


def test_gps_fixes_by_trace_number_outside_and_headings(tmp_path):
    """Fixes at scans 2 and 6, 1.853 m apart due east: traces 0-1 and 7-9 take the nearest fix (reported), the
    headings point east."""
    lines = []
    for scan, lon_min in ((2, 18.0000), (6, 18.0025)):
        lines += [f"$GSSIS,{scan},-1", f"$GPGGA,000320,0000.0000,N,000{lon_min:07.4f},E,1,08,1.0,0.0,M,,M,,*00"]
    (tmp_path / "g.dzg").write_text("\n".join(lines) + "\n")
    kind, (scans, pos) = read_track(tmp_path / "g.dzg")
    placed = apply_track(Survey(data=np.zeros((10, 8), np.float32), dt_s=1e-10), (kind, (scans, pos)))
    east = placed.positions_xyz[:, 0] - placed.positions_xyz[0, 0]
    assert east[6] == pytest.approx(0.0025 / 60 * math.pi / 180 * 6_378_137, rel=5e-3)
    np.testing.assert_allclose(east[:3], 0, atol=1e-9)
    np.testing.assert_allclose(east[6:], east[6], rtol=1e-12)
    np.testing.assert_allclose(east[4], east[6] / 2, rtol=1e-9)
    assert placed.metadata["track_warning"] == "5 traces lie outside the GPS fixes' span"
    assert placed.metadata["positions_source"] == "GPS fixes by trace number"
    np.testing.assert_allclose(placed.headings_rad[2:7], 0, atol=1e-9)
    inside = apply_track(Survey(data=np.zeros((5, 8), np.float32), dt_s=1e-10), (kind, (scans - 2, pos)))
    assert "track_warning" not in inside.metadata


def test_a_dzg_whose_fixes_do_not_advance_is_refused(tmp_path):
    lines = []
    for scan in (5, 5):
        lines += [f"$GSSIS,{scan},-1", "$GPGGA,000320,0000.0000,N,00018.0000,E,1,08,1.0,0.0,M,,M,,*00"]
    (tmp_path / "g.dzg").write_text("\n".join(lines) + "\n")
    with pytest.raises(FormatError, match="^g.dzg: GPS fixes do not advance with the scan number$"):
        read_track(tmp_path / "g.dzg")
    (tmp_path / "h.dzg").write_text("\n".join(lines[:2]) + "\n")
    with pytest.raises(FormatError, match=r"^h.dzg: holds 1 GPS fix\(es\) with a fix quality > 0: two at least"):
        read_track(tmp_path / "h.dzg")


def test_more_trajectory_edges(tmp_path):
    p = tmp_path / "q.txt"
    p.write_text("0 1 2 3 0 0 0 1\n1 1 2 3 0 0 0 0\n")  # the second pose's quaternion is zero, the first is not
    with pytest.raises(FormatError, match="^q.txt: holds a zero quaternion$"):
        read_tum(p)
    p.write_text("0 1 2 3 0 0 0 1e-9\n")  # exactly the limit: kept
    np.testing.assert_allclose(read_tum(p).orientations_quat_wxyz, [[1, 0, 0, 0]])
    p.write_bytes(b"# caf\xe9 (latin-1 in a comment)\n0 1 2 3 0 0 0 1\n")  # not UTF-8: replaced, read
    assert read_tum(p).positions_xyz.tolist() == [[1, 2, 3]]
    c = tmp_path / "c.csv"
    c.write_bytes(b"t,x,y,z\n# \xff\n0,1,2,3\n".replace(b"# \xff\n", b""))
    c.write_bytes(b"t,x,y,z,note\n0,1,2,3,\xff\n")
    assert read_csv_trajectory(c).positions_xyz.tolist() == [[1, 2, 3]]
    x = tmp_path / "t.xyz"
    x.write_bytes(b"# \xff\n0 0 0\n1 1 1\n")
    assert read_xyz_track(x).tolist() == [[0, 0, 0], [1, 1, 1]]
    t = tmp_path / "t.csv"
    t.write_bytes(b"x,y,z,\xff\n0,0,0,a\n , , , \n1,1,1,b\n")  # a row of blanks between
    assert read_track(t)[1].tolist() == [[0, 0, 0], [1, 1, 1]]
    t.write_bytes(b"0 0 0\n1 1\n")
    tt = tmp_path / "u.txt"
    tt.write_bytes(b"0 0 0\n1 1\n")
    with pytest.raises(FormatError, match=r"^u.txt: line 2: expected 3 numbers \(x y z\), got 2$"):
        read_track(tt)


def test_attach_track_backwards_and_climbing():
    """A survey whose along-line positions run backwards from its first trace (a reversed line): distances before
    the track's start take its first segment's heading; the heading is the plan direction, not the climb."""
    track = np.array([[0, 0, 0], [2, 0, 1.0], [2, 2, 3.0]])  # climbs 1 m over the first 2 m, 2 m over the next
    s = Survey(data=np.zeros((3, 8), np.float32), dt_s=1e-10,
               positions_xyz=np.c_[[0.0, -0.5, 1.0], np.zeros(3), np.zeros(3)])
    out = attach_track(s, track)
    np.testing.assert_allclose(out.headings_rad, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(out.positions_xyz[:, 2], [0.0, 0.0, 0.5])
    up = s.replace(positions_xyz=np.c_[[0.0, 2.5, 3.0], np.zeros(3), np.zeros(3)])
    np.testing.assert_allclose(attach_track(up, track).headings_rad, [0.0, np.pi / 2, np.pi / 2])
    exact = s.replace(positions_xyz=np.c_[[0.0, 1.0, 4.2], np.zeros(3), np.zeros(3)])  # 4.2 m on 4 m: 1.05 exactly
    assert "track_warning" not in attach_track(exact, track).metadata


def test_gps_fixes_three_and_north_east(tmp_path):
    """Three fixes at scans 1, 3, 5 running north twice as fast as east: traces 0 and 6 outside their span;
    headings atan2(2, 1) = 63.4 deg."""
    lines = []
    for scan, minutes in ((1, 0.0), (3, 0.001), (5, 0.002)):
        lines += [f"$GSSIS,{scan},-1",
                  f"$GPGGA,000320,00{2 * minutes:07.4f},N,000{minutes:07.4f},E,1,08,1.0,0.0,M,,M,,*00"]
    (tmp_path / "g.dzg").write_text("\n".join(lines) + "\n")
    track = read_track(tmp_path / "g.dzg")
    placed = apply_track(Survey(data=np.zeros((7, 8), np.float32), dt_s=1e-10), track)
    assert placed.metadata["track_warning"] == "2 traces lie outside the GPS fixes' span"
    np.testing.assert_allclose(placed.headings_rad[1:6], np.arctan2(2.0, 1.0), atol=0.01)
