"""APE / RPE through evo against hand computations, and the NEES bounds."""

import numpy as np
import pytest
from scipy.stats import chi2

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.imu import so3_exp
from gpr3d.pose.metrics import aligned_positions, ape, nees, nees_bounds, rpe

pytest.importorskip("evo")


def _path(n=400):
    t = np.linspace(0, 40, n)
    p = np.stack([0.5 * t, 2.0 * np.sin(0.2 * t), 0.01 * np.cos(t)], -1)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    return t, p, q


def test_ape_removes_a_rigid_motion_and_measures_what_is_left():
    t, p, q = _path()
    ref = Trajectory(t, p, q)
    R = so3_exp([0.0, 0.0, 0.7])
    moved = Trajectory(t, p @ R.T + [3.0, -2.0, 0.5], q)
    assert ape(moved, ref)["rmse"] < 1e-9
    assert ape(moved, ref, align=False)["rmse"] > 1.0
    # a zero-mean wobble across the path that no rigid motion can take out: rmse a / sqrt(2)
    a = 0.05
    wob = p + np.stack([np.zeros_like(t), np.zeros_like(t), a * np.sin(2 * np.pi * t / 4.0)], -1)
    res = ape(Trajectory(t, wob, q), ref)
    assert res["rmse"] == pytest.approx(a / np.sqrt(2), rel=0.03) and res["n"] == t.size
    with pytest.raises(InvalidDataError, match="share no timestamps"):
        ape(Trajectory(t + 1000.0, p, q), ref)


def test_rpe_measures_drift_per_metre():
    t, p, q = _path()
    ref = Trajectory(t, p, q)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    drift = p + np.stack([0.01 * s, np.zeros_like(s), np.zeros_like(s)], -1)  # 1 cm per metre along x
    res = rpe(Trajectory(t, drift, q), ref, delta_m=1.0)
    assert 0.002 < res["mean"] < 0.0125  # at most 1 cm per metre, less where the path turns off x


def test_nees_of_drawn_errors_follows_chi_square():
    rng = np.random.default_rng(1)
    n = 4000
    L = np.tril(rng.normal(size=(6, 6))) * 0.01 + np.eye(6) * 0.01
    cov = L @ L.T
    e = rng.multivariate_normal(np.zeros(6), cov, n)
    R_est = np.tile(np.eye(3), (n, 1, 1))
    R_true = np.stack([so3_exp(v) for v in e[:, :3]])
    p_est = np.zeros((n, 3))
    vals = nees(R_est, p_est, np.tile(cov, (n, 1, 1)), R_true, e[:, 3:])
    assert vals.mean() == pytest.approx(6.0, rel=0.05)
    lo, hi = nees_bounds(1)
    assert (lo, hi) == pytest.approx(tuple(chi2.ppf([0.025, 0.975], 6)))
    assert np.mean((vals >= lo) & (vals <= hi)) == pytest.approx(0.95, abs=0.015)


def test_metrics_by_hand_on_gentle_runs():
    """A run at about 1 m/s on a gentle bend: an estimate shifted by (0.3, 0.4, 0) has APE 0.5 m everywhere without
    alignment and 0 with it; one stretched by 1 % along the run drifts 1 cm per metre (RPE over 1 m, and 2 cm over 2 m), which
    no rigid alignment changes; a stretched copy's APE needs the scale it is not allowed (SE(3), not Sim(3))."""
    t = np.arange(0.0, 20.0, 0.1)
    p = np.c_[t, 0.3 * np.sin(0.1 * t), np.zeros_like(t)]
    q = np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    ref = Trajectory(t, p, q)
    shifted = Trajectory(t, p + [0.3, 0.4, 0.0], q)
    res = ape(shifted, ref, align=False)
    assert res == {"rmse": pytest.approx(0.5), "mean": pytest.approx(0.5), "max": pytest.approx(0.5), "n": t.size}
    assert ape(shifted, ref)["max"] < 1e-9
    np.testing.assert_allclose(aligned_positions(shifted, ref), p, atol=1e-9)
    stretched = Trajectory(t, 1.01 * p, q)
    r1 = rpe(stretched, ref)
    assert r1["delta_m"] == 1.0 and r1["rmse"] == pytest.approx(0.01, rel=0.02)
    assert r1["mean"] == pytest.approx(0.01, rel=0.02) and r1["max"] == pytest.approx(0.01, rel=0.02)
    assert rpe(stretched, ref, delta_m=2.0)["mean"] == pytest.approx(0.02, rel=0.02)
    assert ape(Trajectory(t, 2.0 * p, q), ref)["rmse"] > 1.0  # no scale correction
    # timestamps match within 1 ms, not beyond
    assert ape(Trajectory(t + 0.0005, p, q), ref)["n"] == t.size
    with pytest.raises(InvalidDataError, match=r"^the two trajectories share no timestamps \(within 1 ms\): are they "
                                               r"on one clock\?$"):
        ape(Trajectory(t + 0.002, p, q), ref)


def test_nees_by_hand_and_its_bounds_over_runs():
    I3 = np.eye(3)
    # position error only: e = p_true - p_est = (0, 0.1, 0) with a 0.01 m^2 variance: NEES 1
    cov = np.diag([1e-4, 1e-4, 1e-4, 0.01, 0.01, 0.01])[None]
    assert nees(I3[None], [[1.0, 2.0, 3.0]], cov, I3[None], [[1.0, 2.1, 3.0]])[0] == pytest.approx(1.0)
    assert nees(I3[None], [[1.0, 2.0, 3.0]], cov, I3[None], [[1.0, 2.0, 3.0]])[0] == pytest.approx(0.0, abs=1e-12)
    lo, hi = nees_bounds(5)
    assert (lo, hi) == pytest.approx(tuple(chi2.ppf([0.025, 0.975], 30) / 5))
    assert nees_bounds(4, dof=3, prob=0.9) == pytest.approx(tuple(chi2.ppf([0.05, 0.95], 12) / 4))
