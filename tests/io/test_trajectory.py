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


@pytest.mark.parametrize("text, msg", [
    ("0 1 2 3 0 0 0\n", "expected 8 numbers"),
    ("0 1 2 x 0 0 0 1\n", "not a number"),
    ("0 1 2 3 0 0 0 0\n", "zero quaternion"),
    ("0 nan 2 3 0 0 0 1\n", "NaN"),
    ("# only a comment\n", "no poses"),
])
def test_bad_tum(tmp_path, text, msg):
    p = tmp_path / "bad.txt"
    p.write_text(text)
    with pytest.raises(FormatError, match=msg):
        read_tum(p)


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
