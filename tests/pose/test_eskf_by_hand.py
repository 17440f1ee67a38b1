"""The fusion filter's pieces by hand: settings and their messages, the invariant error and its inverse, one
Kalman correction written out, the measurement Jacobians against numerical derivatives of the measurements, the
still start's alignment, and the camera-to-IMU motion."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.inertial import ImuSamples
from gpr3d.pose import eskf
from gpr3d.pose.imu import GRAVITY, so3_exp, so3_log


@pytest.mark.parametrize("kw, message", [
    (dict(gate_prob=1.0), "gate_prob must lie in (0, 1), got 1.0"),
    (dict(gate_prob=0.0), "gate_prob must lie in (0, 1), got 0.0"),
    (dict(init_still_s=0.0), "init_still_s must be positive, got 0.0"),
    (dict(zupt_window_s=-1.0), "zupt_window_s must be positive, got -1.0"),
    (dict(zupt_sigma_m_s=0.0), "zupt_sigma_m_s must be positive, got 0.0"),
    (dict(sigma_accel_bias=0.0), "sigma_accel_bias must be positive, got 0.0"),
    (dict(sigma_gyro_bias=float("nan")), "sigma_gyro_bias must be positive, got nan"),
    (dict(vo_cov_scale=0.0), "vo_cov_scale must be positive, got 0.0"),
    (dict(flat_ground_sigma_m=0.0), "flat_ground_sigma_m must be positive, got 0.0"),
    (dict(wheel_sigma_frac=0.0), "wheel_sigma_frac must be positive, got 0.0"),
    (dict(wheel_sigma_m=-0.001), "wheel_sigma_m must be positive, got -0.001"),
    (dict(imu_T_camera=np.eye(3)), "imu_T_camera must be a finite 4 x 4 pose, got shape (3, 3)"),
    (dict(imu_T_antenna=np.full((4, 4), np.nan)), "imu_T_antenna must be a finite 4 x 4 pose, got shape (4, 4)"),
    (dict(imu_T_antenna=np.diag([1.0, 1.0, -1.0, 1.0])), "imu_T_antenna: its 3 x 3 block is not a rotation"),
    (dict(imu_T_camera=np.diag([2.0, 1.0, 1.0, 1.0])), "imu_T_camera: its 3 x 3 block is not a rotation"),
])
def test_settings_messages_in_full(kw, message):
    with pytest.raises(InvalidDataError) as err:
        eskf.EskfConfig(**kw)
    assert str(err.value) == message


def test_defaults_and_a_flat_ground_left_unset():
    c = eskf.EskfConfig()
    assert (c.gate_prob, c.init_still_s, c.zupt, c.zupt_window_s, c.zupt_speed_m_s, c.zupt_sigma_m_s) == \
        (0.999, 1.0, True, 0.25, 0.01, 0.003)
    assert (c.sigma_accel_bias, c.sigma_gyro_bias, c.vo_cov_scale, c.wheel_sigma_frac, c.wheel_sigma_m) == \
        (0.1, 0.002, 1.0, 0.01, 0.001)
    assert c.flat_ground_sigma_m is None and c.camera_time_offset_s == 0.0
    assert np.array_equal(c.imu_T_camera, np.eye(4)) and c.imu_T_antenna.dtype == np.float64


def _state(rng):
    R = so3_exp(rng.normal(size=3))
    Rc = so3_exp(rng.normal(size=3))
    return (rng.normal(size=3), rng.normal(size=3), R, rng.normal(size=3), rng.normal(size=3), rng.normal(size=3), Rc)


def test_the_invariant_error_and_its_inverse_by_hand():
    rng = np.random.default_rng(2)
    b = _state(rng)
    d = rng.normal(size=21) * 0.3
    a = eskf._plus(b, d)
    E, Ec = so3_exp(d[6:9]), so3_exp(d[18:21])
    np.testing.assert_allclose(a[2], E @ b[2], atol=1e-14)  # R_true = Exp(dtheta) R
    np.testing.assert_allclose(a[0], E @ b[0] + d[0:3], atol=1e-14)  # p_true = Exp(dtheta) p + dp
    np.testing.assert_allclose(a[1], E @ b[1] + d[3:6], atol=1e-14)
    np.testing.assert_allclose(a[3], b[3] + d[9:12], atol=1e-15)
    np.testing.assert_allclose(a[4], b[4] + d[12:15])
    np.testing.assert_allclose(a[5], Ec @ b[5] + d[15:18], atol=1e-14)
    np.testing.assert_allclose(a[6], Ec @ b[6], atol=1e-14)
    np.testing.assert_allclose(eskf._minus(a, b), d, atol=1e-12)
    assert not eskf._minus(b, b).any()


def _filter(rng):
    f = eskf._Filter(eskf.EskfConfig(), so3_exp([0.1, -0.05, 0.3]), np.zeros(3))
    f.p, f.v = rng.normal(size=3), rng.normal(size=3) * 0.3
    f.pc, f.Rc = rng.normal(size=3), so3_exp(rng.normal(size=3) * 0.2)
    A = rng.normal(size=(21, 21)) * 0.05
    f.P = A @ A.T + np.eye(21) * 1e-3
    return f


def test_one_correction_written_out():
    rng = np.random.default_rng(3)
    f = _filter(rng)
    before = f.state()
    P = f.P.copy()
    H = rng.normal(size=(2, 21))
    r = np.array([0.02, -0.01])
    Rm = np.diag([1e-3, 2e-3])
    assert f._correct(H, r, Rm, None)
    S = H @ P @ H.T + Rm
    K = P @ H.T @ np.linalg.inv(S)
    dx = K @ r
    want = np.eye(21) - K @ H
    np.testing.assert_allclose(f.P, want @ P @ want.T + K @ Rm @ K.T, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(eskf._minus(f.state(), before), dx, rtol=1e-9, atol=1e-13)
    np.testing.assert_array_equal(f.P, f.P.T)
    # the gate: a residual of Mahalanobis distance past it is refused and changes nothing
    g = _filter(np.random.default_rng(3))
    d2 = float(r @ np.linalg.inv(H @ g.P @ H.T + Rm) @ r)
    P0 = g.P.copy()
    assert not g._correct(H, r, Rm, d2 * 0.999) and np.array_equal(g.P, P0)
    assert g._correct(H, r, Rm, d2 * 1.001)


def _numeric_H(f, meas):
    """d meas(state (+) dx) / d dx at 0, by central differences on the invariant error."""
    base = f.state()
    cols = []
    for j in range(21):
        d = np.zeros(21)
        d[j] = 1e-6
        cols.append((meas(eskf._plus(base, d)) - meas(eskf._plus(base, -d))) / 2e-6)
    return np.stack(cols, 1)


def test_the_measurement_jacobians_are_the_measurements_derivatives():
    rng = np.random.default_rng(4)
    f = _filter(rng)
    x = f.state()
    rel_p = lambda s: s[6].T @ (s[0] - s[5])  # noqa: E731 - the motion since the clone, in the clone's frame
    np.testing.assert_allclose(f._h_position(np.eye(3)), _numeric_H(f, rel_p), rtol=1e-6, atol=1e-7)
    rel_R = lambda s: so3_log(x[2].T @ x[6] @ (s[6].T @ s[2]))  # noqa: E731 - the turn since the clone, about x's
    H = np.zeros((6, 21))
    H[:3, 6:9], H[:3, 18:21] = f.R.T, -f.R.T
    np.testing.assert_allclose(H[:3], _numeric_H(f, rel_R), rtol=1e-5, atol=1e-6)
    vel = lambda s: s[1]  # noqa: E731
    Hs = np.zeros((3, 21))
    Hs[:, 3:6] = np.eye(3)
    Hs[:, 6:9] = -eskf.skew(f.v)
    np.testing.assert_allclose(Hs, _numeric_H(f, vel), rtol=1e-6, atol=1e-7)
    height = lambda s: np.array([s[0][2]])  # noqa: E731
    Hh = np.zeros((1, 21))
    Hh[0, 2] = 1.0
    Hh[0, 6:9] = -eskf.skew(f.p)[2]
    np.testing.assert_allclose(Hh, _numeric_H(f, height), rtol=1e-6, atol=1e-7)


def _twin(seed):
    return _filter(np.random.default_rng(seed)), _filter(np.random.default_rng(seed))


def _same(a, b):
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-15)
    for u, w in zip(a.state(), b.state()):
        np.testing.assert_allclose(u, w, rtol=1e-12, atol=1e-15)


def test_each_update_is_one_correction_with_its_jacobian_residual_and_noise():
    from scipy.stats import chi2

    f, g = _twin(5)
    f.update_still(0.003)
    H = np.zeros((3, 21))
    H[:, 3:6], H[:, 6:9] = np.eye(3), -eskf.skew(g.v)
    g._correct(H, -g.v, np.eye(3) * 0.003**2, None)
    _same(f, g)
    f, g = _twin(6)
    f.update_height(0.02)
    H = np.zeros((1, 21))
    H[0, 2], H[0, 6:9] = 1.0, -eskf.skew(g.p)[2]
    g._correct(H, np.array([-g.p[2]]), np.array([[0.02**2]]), None)
    _same(f, g)
    f, g = _twin(7)
    fwd = (g.Rc.T @ (g.p - g.pc))[0]
    assert f.update_forward(fwd + 0.01, 0.05)
    assert g._correct(g._h_position(np.array([[1.0, 0.0, 0.0]])), np.array([0.01]), np.array([[0.05**2]]),
                      float(chi2.ppf(0.999, 1)))
    _same(f, g)
    f, _ = _twin(8)
    fwd = (f.Rc.T @ (f.p - f.pc))[0]
    Hf = f._h_position(np.array([[1.0, 0, 0]]))
    S = float((Hf @ f.P @ Hf.T)[0, 0]) + 0.05**2
    big = math.sqrt(chi2.ppf(0.999, 1) * S) * 1.01
    assert not f.update_forward(fwd + big, 0.05)  # just past the 0.999 gate: refused
    assert _filter(np.random.default_rng(8)).update_forward(fwd + big / 1.02, 0.05)  # just inside: taken
    f, g = _twin(9)
    Rz, pz = so3_exp([0.01, 0.02, -0.03]) @ (g.Rc.T @ g.R), g.Rc.T @ (g.p - g.pc) + np.array([0.01, 0.0, -0.02])
    cov = np.diag([1e-4] * 3 + [1e-3] * 3)
    assert f.update_relative(Rz, pz, cov, 100.0)
    H = np.zeros((6, 21))
    H[:3, 6:9], H[:3, 18:21] = g.R.T, -g.R.T
    H[3:] = g._h_position(np.eye(3))
    r = np.concatenate([so3_log((g.Rc.T @ g.R).T @ Rz), pz - g.Rc.T @ (g.p - g.pc)])
    g._correct(H, r, cov, 100.0)
    _same(f, g)
    # odometry far off is refused by the gate it is given, and changes nothing
    h, _ = _twin(9)
    P0 = h.P.copy()
    assert not h.update_relative(Rz, pz + 50.0, cov, 100.0) and np.array_equal(h.P, P0)


def test_pose_covariance_in_the_body_convention_by_hand():
    rng = np.random.default_rng(9)
    f = _filter(rng)
    # the map from the invariant error to (Log(R^T R_true), p_true - p), by derivatives: cov = J P J^T
    x = f.state()
    cols = []
    for j in range(6):
        idx = [6, 7, 8, 0, 1, 2][j]
        d = np.zeros(21)
        d[idx] = 1e-6
        xp, xm = eskf._plus(x, d), eskf._plus(x, -d)
        y = lambda s: np.concatenate([so3_log(x[2].T @ s[2]), s[0] - x[0]])  # noqa: E731
        cols.append((y(xp) - y(xm)) / 2e-6)
    J = np.stack(cols, 1)
    idx = [6, 7, 8, 0, 1, 2]
    want = J @ f.P[np.ix_(idx, idx)] @ J.T
    np.testing.assert_allclose(f.pose_cov(), want, rtol=1e-5, atol=1e-10)


def test_the_still_start_gives_roll_pitch_and_the_gyro_bias():
    rng = np.random.default_rng(10)
    R0 = Rotation.from_euler("ZYX", [0.0, 0.1, -0.2]).as_matrix()
    n = 200
    t = np.arange(n) * 0.005
    f = np.tile(R0.T @ np.array([0.0, 0.0, GRAVITY]), (n, 1)) + rng.normal(0, 0.01, (n, 3))
    g = np.array([0.01, -0.02, 0.005]) + rng.normal(0, 0.001, (n, 3))
    imu = ImuSamples(t, f, g)
    R, bg = eskf._align(imu.t_s, imu.accel, imu.gyro, 0.5)
    sel = t <= 0.5
    u = f[sel].mean(0) / np.linalg.norm(f[sel].mean(0))
    want = Rotation.from_euler("ZYX", [0.0, math.atan2(-u[0], math.hypot(u[1], u[2])), math.atan2(u[1], u[2])])
    np.testing.assert_allclose(R, want.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(R, R0, atol=0.01)
    np.testing.assert_allclose(bg, g[sel].mean(0), rtol=1e-12)
    with pytest.raises(InvalidDataError, match=r"^gravity alignment needs at least 10 IMU samples in the first "
                                               r"0.04 s$"):
        eskf._align(imu.t_s, imu.accel, imu.gyro, 0.04)  # 9 samples
    assert eskf._align(imu.t_s, imu.accel, imu.gyro, 0.045)[0].shape == (3, 3)  # 10 samples are enough
    shaken = ImuSamples(t, f + rng.normal(0, 1.0, (n, 3)), g)
    with pytest.raises(InvalidDataError, match=r"^the cart is not still in the first 0.5 s \(accelerometer spread "
                                               r"1\.\d\d m/s\^2\): start the recording at rest, or lower init_still_s$"):
        eskf._align(shaken.t_s, shaken.accel, shaken.gyro, 0.5)


def test_camera_motion_to_imu_motion_and_its_covariance_by_derivatives():
    rng = np.random.default_rng(11)
    T = np.eye(4)
    T[:3, :3] = so3_exp([0.3, -0.2, 1.0])
    T[:3, 3] = [0.1, -0.05, 0.2]
    Rc, pc = so3_exp([0.05, 0.02, -0.1]), np.array([0.3, 0.01, -0.02])
    A = rng.normal(size=(6, 6)) * 0.01
    cov = A @ A.T
    Rb, pb, cb = eskf.camera_to_imu_motion(Rc, pc, cov, T)
    # the IMU's motion: T_bc (camera motion) T_bc^-1
    M = T @ np.block([[Rc, pc[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]) @ np.linalg.inv(T)
    np.testing.assert_allclose(Rb, M[:3, :3], atol=1e-14)
    np.testing.assert_allclose(pb, M[:3, 3], atol=1e-14)

    def imu_of(d):  # the camera's motion perturbed (rotation on the right, as the odometry's covariance is)
        Rp, pp = Rc @ so3_exp(d[:3]), pc + d[3:]
        Rb2, pb2, _ = eskf.camera_to_imu_motion(Rp, pp, cov, T)
        return np.concatenate([so3_log(Rb.T @ Rb2), pb2 - pb])

    J = np.stack([(imu_of(e * 1e-6) - imu_of(-e * 1e-6)) / 2e-6 for e in np.eye(6)], 1)
    np.testing.assert_allclose(cb, J @ cov @ J.T, rtol=1e-4, atol=1e-12)


def _propagated(x, fm, wm, dt, P=None):
    g = _filter(np.random.default_rng(1))
    g.p, g.v, g.R, g.ba, g.bg, g.pc, g.Rc = [np.array(a, copy=True) for a in x]
    if P is not None:
        g.P = P.copy()
    g.Phi = np.eye(15)
    g.propagate(fm, wm, dt)
    return g


def test_one_step_s_nominal_state_transition_and_noise_by_derivatives():
    rng = np.random.default_rng(1)
    f = _filter(rng)
    f.ba, f.bg = rng.normal(size=3) * 0.1, rng.normal(size=3) * 0.01
    x0 = f.state()
    fm, wm, dt = np.array([0.3, -0.2, 9.9]), np.array([0.2, -0.1, 0.5]), 1e-3
    y = _propagated(x0, fm, wm, dt, P=np.zeros((21, 21)))
    # the nominal state: the specific force at the step's midpoint attitude, gravity along -z
    fb, wb = fm - x0[3], wm - x0[4]
    a = x0[2] @ so3_exp(0.5 * wb * dt) @ fb - np.array([0.0, 0.0, GRAVITY])
    np.testing.assert_allclose(y.p, x0[0] + x0[1] * dt + 0.5 * a * dt * dt, rtol=0, atol=1e-15)
    np.testing.assert_allclose(y.v, x0[1] + a * dt, rtol=0, atol=1e-14)
    np.testing.assert_allclose(y.R, x0[2] @ so3_exp(wb * dt), rtol=0, atol=1e-15)
    assert np.array_equal(y.pc, x0[5]) and np.array_equal(y.Rc, x0[6])  # the clone stays
    # the transition: the derivative of the step in the invariant error (second order in dt left over)
    y0 = y.state()
    cols = []
    for j in range(15):
        d = np.zeros(21)
        d[j] = 1e-7
        hi = eskf._minus(_propagated(eskf._plus(x0, d), fm, wm, dt).state(), y0)
        lo = eskf._minus(_propagated(eskf._plus(x0, -d), fm, wm, dt).state(), y0)
        cols.append((hi - lo) / 2e-7)
    Jn = np.stack(cols, 1)[:15]
    assert np.abs(y.Phi - Jn).max() < 5e-6 and np.abs(Jn - np.eye(15)).max() > 5e-3
    # the process noise from zero covariance: white accelerometer and gyro noise through the step's sensitivity to
    # them (variance q / dt per sample), and the bias walks
    def sens(k):
        cols = []
        for e in np.eye(3):
            up = _propagated(x0, fm + e * 1e-6 * (k == 0), wm + e * 1e-6 * (k == 1), dt).state()
            dn = _propagated(x0, fm - e * 1e-6 * (k == 0), wm - e * 1e-6 * (k == 1), dt).state()
            cols.append((eskf._minus(up, y0) - eskf._minus(dn, y0)) / 2e-6)
        return np.stack(cols, 1)[:15]

    qa, qg, qba, qbg = y.q
    Jf, Jw = sens(0), sens(1)
    Q = Jf @ Jf.T * qa / dt + Jw @ Jw.T * qg / dt
    Q[9:12, 9:12] += np.eye(3) * qba * dt
    Q[12:15, 12:15] += np.eye(3) * qbg * dt
    np.testing.assert_allclose(y.P[:15, :15], Q, rtol=0, atol=2e-3 * np.abs(Q).max())
    # the bias walks alone drive the biases (far under the tolerance above): exactly q dt from a zero covariance
    np.testing.assert_allclose(y.P[9:12, 9:12], np.eye(3) * qba * dt, rtol=1e-12, atol=0)
    np.testing.assert_allclose(y.P[12:15, 12:15], np.eye(3) * qbg * dt, rtol=1e-12, atol=0)
    assert not y.P[15:].any() and not y.P[:, 15:].any()
    n = eskf.EskfConfig().imu_noise
    assert (qa, qg, qba, qbg) == (n.accel_noise**2, n.gyro_noise**2, n.accel_bias_walk**2, n.gyro_bias_walk**2)
    # with a covariance: F P F^T + Q, and the cross terms with the clone carried by F
    P0 = _filter(np.random.default_rng(12)).P
    z = _propagated(x0, fm, wm, dt, P=P0)
    F = z.Phi
    np.testing.assert_allclose(z.P[:15, :15], F @ P0[:15, :15] @ F.T + y.P[:15, :15], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(z.P[:15, 15:], F @ P0[:15, 15:], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(z.P[15:, 15:], P0[15:, 15:], rtol=0, atol=0)
    np.testing.assert_array_equal(z.P, z.P.T)


def test_a_clone_copies_the_pose_and_its_covariance_rows():
    f = _filter(np.random.default_rng(13))
    P = f.P.copy()
    f.clone()
    assert np.array_equal(f.pc, f.p) and np.array_equal(f.Rc, f.R) and f.pc is not f.p
    core = [0, 1, 2, 6, 7, 8]
    np.testing.assert_array_equal(f.P[:15, :15], P[:15, :15])
    np.testing.assert_array_equal(f.P[15:, :15], P[core, :15])
    np.testing.assert_array_equal(f.P[:15, 15:], P[:15, core])
    np.testing.assert_array_equal(f.P[15:, 15:], P[np.ix_(core, core)])


def test_the_start_covariance_by_hand():
    R0 = so3_exp([0.1, -0.05, 0.3])
    cfg = eskf.EskfConfig(sigma_accel_bias=0.2, sigma_gyro_bias=0.003)
    f = eskf._Filter(cfg, R0, np.array([0.01, 0.0, -0.01]))
    g_b = R0.T @ np.array([0.0, 0.0, GRAVITY])
    M = eskf.skew(g_b) / GRAVITY**2
    Pb = np.diag([1e-8] * 3 + [1e-4] * 3 + [1e-8] * 3 + [0.04] * 3 + [0.003**2] * 3)
    Pb[6:9, 6:9] += 0.04 * M @ M.T  # tilt errs by the accelerometer bias across gravity
    Pb[6:9, 9:12] = 0.04 * M
    Pb[9:12, 6:9] = Pb[6:9, 9:12].T
    T = np.eye(15)
    T[6:9, 6:9] = R0
    want = T @ Pb @ T.T
    np.testing.assert_allclose(f.P[:15, :15], want, rtol=1e-12, atol=1e-18)
    core = [0, 1, 2, 6, 7, 8]
    np.testing.assert_allclose(f.P[15:, 15:], want[np.ix_(core, core)], rtol=1e-12, atol=1e-18)
    assert np.array_equal(f.bg, [0.01, 0.0, -0.01]) and not f.p.any() and not f.v.any() and not f.ba.any()
    assert np.array_equal(f.Phi, np.eye(15)) and f.nodes is None


def test_a_singular_innovation_is_refused_and_the_gate_is_strict():
    f = _filter(np.random.default_rng(13))
    P0 = f.P.copy()
    assert not f._correct(np.zeros((1, 21)), np.array([1.0]), np.zeros((1, 1)), None)  # S = 0: no inverse
    assert np.array_equal(f.P, P0)
    # S = 1 exactly (H = 0, noise 1): r^2 = 4 equal to the gate passes, a gate of 4 - ulp refuses
    assert f._correct(np.zeros((1, 21)), np.array([2.0]), np.ones((1, 1)), 4.0)
    assert not f._correct(np.zeros((1, 21)), np.array([2.0]), np.ones((1, 1)), np.nextafter(4.0, 0.0))


def test_poses_are_checked_with_a_tolerance_and_kept_as_floats():
    c = eskf.EskfConfig(imu_T_camera=np.eye(4, dtype=int))
    assert c.imu_T_camera.dtype == np.float64
    T = np.eye(4)
    T[0, 1] = 5e-7  # R^T R off the identity by 5e-7: within the 1e-6 allowed
    assert eskf.EskfConfig(imu_T_antenna=T).imu_T_antenna[0, 1] == 5e-7
    T = np.eye(4)
    T[0, 0] = 1 - 1e-7  # determinant just under 1: a rotation still
    assert eskf.EskfConfig(imu_T_antenna=T).imu_T_antenna[0, 0] == 1 - 1e-7
    T = np.eye(4)
    T[0, 0] = 1.1  # R^T R off by 0.21
    with pytest.raises(InvalidDataError, match=r"^imu_T_antenna: its 3 x 3 block is not a rotation$"):
        eskf.EskfConfig(imu_T_antenna=T)


def test_the_still_start_allows_an_accelerometer_spread_of_half_a_metre_per_second_squared():
    t = np.arange(10) * 0.1
    for amp, still in ((0.5, True), (1.0, False)):  # x alternates +-amp: its spread is amp exactly
        f = np.zeros((10, 3))
        f[:, 0] = amp * (-1.0) ** np.arange(10)
        f[:, 2] = GRAVITY
        imu = ImuSamples(t, f, np.zeros((10, 3)))
        if still:
            assert eskf._align(imu.t_s, imu.accel, imu.gyro, 1.0)[0].shape == (3, 3)
        else:
            with pytest.raises(InvalidDataError, match=r"accelerometer spread 1\.00 m/s\^2"):
                eskf._align(imu.t_s, imu.accel, imu.gyro, 1.0)


def test_the_antenna_trajectory_carries_the_lever_arm_and_the_mount_rotation_by_hand():
    n = 2
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 degrees about z
    Ta = np.eye(4)
    Ta[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # 90 degrees about x
    Ta[:3, 3] = [0.1, 0.2, 0.3]
    z = np.zeros((0,))
    res = eskf.FusionResult(np.array([0.0, 0.5]), np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]]), np.zeros((n, 3)),
                            np.stack([Rz, np.eye(3)]), np.zeros((n, 3)), np.zeros((n, 3)), z, np.zeros((0, 6, 6)),
                            z.astype(int), np.zeros((0, 3)), np.zeros((0, 3, 3)), z.astype(bool), z.astype(bool), z, Ta)
    tr = res.antenna_trajectory()
    np.testing.assert_array_equal(tr.timestamps_s, [0.0, 0.5])
    # Rz [0.1, 0.2, 0.3] = [-0.2, 0.1, 0.3]
    np.testing.assert_allclose(tr.positions_xyz, [[0.8, 2.1, 3.3], [0.1, 0.2, 0.3]], rtol=0, atol=1e-15)
    # z90 then x90: q = (cos45, 0, 0, sin45) (cos45, sin45, 0, 0) = (1/2, 1/2, 1/2, 1/2); x90 alone: (c, s, 0, 0)
    s = math.sqrt(0.5)
    q = tr.orientations_quat_wxyz * np.sign(tr.orientations_quat_wxyz[:, :1])
    np.testing.assert_allclose(q, [[0.5, 0.5, 0.5, 0.5], [s, s, 0.0, 0.0]], rtol=0, atol=1e-12)
