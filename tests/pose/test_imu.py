"""The IMU helpers by hand: the skew matrix, SO(3) exp/log against Rodrigues' formula, the noise figures."""

import math

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.imu import GRAVITY, ImuNoise, skew, so3_exp, so3_log


def test_skew_is_the_cross_product_matrix():
    v, w = np.array([1.5, -2.0, 0.25]), np.array([-0.5, 3.0, 4.0])
    S = skew(v)
    assert S.tolist() == [[0.0, -0.25, -2.0], [0.25, 0.0, -1.5], [2.0, 1.5, 0.0]]
    np.testing.assert_allclose(S @ w, np.cross(v, w), rtol=1e-15, atol=0)
    assert skew([1, 2, 3]).dtype == np.float64


def _rodrigues(r):
    th = np.linalg.norm(r)
    if th == 0:
        return np.eye(3)
    k = r / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


@pytest.mark.parametrize("r", [[0.0, 0.0, 0.0], [0.0, 0.0, math.pi / 2], [0.3, -0.2, 0.9], [1e-9, 0, 0],
                               [2.0, 1.0, -0.5]])
def test_so3_exp_is_rodrigues_and_log_inverts_it(r):
    r = np.asarray(r)
    R = so3_exp(r)
    np.testing.assert_allclose(R, _rodrigues(r), rtol=0, atol=1e-14)
    np.testing.assert_allclose(so3_log(R), r, rtol=0, atol=1e-12)
    assert so3_exp([0, 0, math.pi / 2]) @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0], abs=1e-15)  # +90 about z


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-9, 3e-8, 1e-7, 1e-5, 9e-5, 1e-4, 0.01, 0.5, 1.5, 2.5, 3.0,
                                   math.pi - 1e-3, math.pi - 1e-7])
def test_one_rotation_by_hand_agrees_with_scipy_at_every_angle(angle):
    """so3_exp / so3_log of one vector or matrix are written out (Rodrigues; the quaternion by Shepperd's rule):
    they agree with SciPy's Rotation (an independent implementation) on random axes at angles from 0 (their
    series) to within 1e-7 of half a turn (where the largest quaternion term moves off w), and several at once
    still go to SciPy. Tolerances: 1e-14 is 45 units in the last place of 1.0, against the 4 (8.9e-16) seen over
    18,000 draws here: libm's and NumPy's sin/cos (SciPy's path) may differ by a few units between hosts, while the
    plausible slips (a series term's sign, a branch's index) move R or the vector by 1e-13 or more."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(int(angle * 1e3) + 7)
    axes = rng.normal(size=(40, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    for r in axes * angle:
        R = so3_exp(r)
        np.testing.assert_allclose(R, Rotation.from_rotvec(r).as_matrix(), rtol=0, atol=1e-14)
        back = so3_log(R)
        # (within 0.15 rad of a half turn the log is ill-conditioned: the matrix's rounding moves it by 1e-8)
        tol = 1e-8 if angle > 3 else 1e-14
        np.testing.assert_allclose(back, Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=tol)
        np.testing.assert_allclose(back, r, rtol=0, atol=tol)
    many = axes[:5] * angle
    np.testing.assert_allclose(so3_exp(many), Rotation.from_rotvec(many).as_matrix(), rtol=0, atol=1e-14)
    np.testing.assert_allclose(so3_log(so3_exp(many)), Rotation.from_rotvec(many).as_rotvec(), rtol=0,
                               atol=1e-8 if angle > 3 else 1e-13)
    assert so3_exp(axes[0] * angle).shape == (3, 3) and so3_log(np.eye(3)).shape == (3,)


def test_one_rotation_never_reaches_scipy_and_whole_numbers_are_taken(monkeypatch):
    """One vector or matrix is done by hand (SciPy's per-call cost was half the pose fusion's time); integers in,
    floats out."""
    import gpr3d.pose.imu as imu

    class NoScipy:
        def __getattr__(self, name):
            raise AssertionError("SciPy's Rotation called for one rotation")

    R = so3_exp(np.array([0.3, -0.2, 0.1]))
    monkeypatch.setattr(imu, "Rotation", NoScipy())
    np.testing.assert_array_equal(so3_exp([0.3, -0.2, 0.1]), R)
    assert so3_log(R) == pytest.approx([0.3, -0.2, 0.1], abs=1e-14)
    assert so3_exp([0, 0, 0]).tolist() == np.eye(3).tolist() and so3_exp([0, 0, 0]).dtype == np.float64
    rot = so3_log(np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]))  # +90 deg about z, as integers
    assert rot.dtype == np.float64 and rot == pytest.approx([0, 0, math.pi / 2], abs=1e-14)


@pytest.mark.parametrize("bad", [[np.inf, 0.0, 0.0], [0.0, np.nan, 0.0], [-np.inf, np.inf, 1.0]])
def test_a_vector_that_is_not_finite_gives_nan_as_scipy_does(bad):
    """(a diverged filter's state must not raise from math.sin of inf)"""
    R = so3_exp(bad)
    assert R.shape == (3, 3) and np.isnan(R).all()


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_half_turns_about_each_axis(axis):
    """A half turn (the quaternion's w is 0: the other three branches of Shepperd's rule) and its log (1e-14: tens
    of units in the last place, a few host to host; near a half turn the log's error grows as 1 / (pi - angle))."""
    r = np.zeros(3)
    r[axis] = math.pi
    R = so3_exp(r)
    np.testing.assert_allclose(R, np.diag([1.0 if i == axis else -1.0 for i in range(3)]), rtol=0, atol=1e-14)
    back = so3_log(R)
    assert abs(back[axis]) == pytest.approx(math.pi, abs=1e-14) and np.abs(np.delete(back, axis)).max() < 1e-14
    # slightly off a half turn about a tilted axis: the branch of the largest diagonal term
    k = np.array([0.1, 0.2, 0.3])
    k[axis] = 1.0
    k /= np.linalg.norm(k)
    r = k * (math.pi - 0.05)
    np.testing.assert_allclose(so3_log(so3_exp(r)), r, rtol=0, atol=1e-12)


def test_imu_noise_defaults_are_the_datasheet_figures_and_bad_ones_are_named():
    n = ImuNoise()
    assert GRAVITY == 9.80665
    assert n.accel_noise == pytest.approx(150e-6 * 9.80665, rel=1e-15, abs=0)
    assert n.gyro_noise == pytest.approx(0.014 * math.pi / 180, rel=1e-15, abs=0)
    assert (n.accel_bias_walk, n.gyro_bias_walk) == (3e-4, 2e-5)
    for name in ("accel_noise", "gyro_noise", "accel_bias_walk", "gyro_bias_walk"):
        for bad in (0.0, -1.0, float("nan"), float("inf")):
            with pytest.raises(InvalidDataError) as err:
                ImuNoise(**{name: bad})
            assert str(err.value) == f"IMU {name.replace('_', ' ')} must be a positive number, got {bad!r}"
    assert ImuNoise(gyro_bias_walk=1e-9).gyro_bias_walk == 1e-9
