"""The fusion driver by hand: ``fuse`` on tiny scripted recordings, with the filter replaced by a spy that logs
every call. The expected call sequence (propagation steps split at the frames, the frames' updates, clones,
zero-velocity updates, wheel and height updates, the smoother's nodes) is written out here from the docstrings'
rules; the outputs must be what the filter held at each step. The smoother's interpolation is checked with the
RTS pass replaced by scripted corrections, and the RTS pass itself against the batch solution of a linear chain."""

import numpy as np
import pytest
from scipy.stats import chi2

from gpr3d.core.inertial import ImuSamples, RelativePoses
from gpr3d.pose import eskf
from gpr3d.pose.imu import GRAVITY, ImuNoise, so3_exp


class _Spy(eskf._Filter):
    """The real filter, logging its calls; ``update_relative`` answers from ``script`` (True: applied)."""

    script: list = []

    def __init__(self, cfg, R0, bg0):
        self.log = []
        self.snaps = []
        self._script = list(type(self).script)
        super().__init__(cfg, R0, bg0)
        type(self).last = self

    def propagate(self, f_m, w_m, dt):
        self.log.append(("propagate", np.array(f_m), np.array(w_m), float(dt)))
        super().propagate(f_m, w_m, dt)

    def node_prior(self, t, i):
        self.log.append(("node_prior", float(t), int(i)))
        super().node_prior(t, i)

    def node_posterior(self, clone_follows, frame):
        self.log.append(("node_posterior", bool(clone_follows), bool(frame)))
        if frame:
            self.snaps.append((self.p.copy(), self.R.copy(), self.pose_cov()))
        super().node_posterior(clone_follows, frame)

    def clone(self):
        self.log.append(("clone",))
        super().clone()

    def update_relative(self, R_z, p_z, cov, gate):
        self.log.append(("update_relative", np.array(R_z), np.array(p_z), np.array(cov), float(gate)))
        ok = self._script.pop(0)
        if ok:
            super().update_relative(R_z, p_z, cov, 1e300)
        return ok

    def update_forward(self, distance_m, sigma_m):
        self.log.append(("update_forward", float(distance_m), float(sigma_m)))
        return super().update_forward(distance_m, sigma_m)

    def update_height(self, sigma_z):
        self.log.append(("update_height", float(sigma_z)))
        super().update_height(sigma_z)

    def update_still(self, sigma):
        self.log.append(("update_still", float(sigma)))
        super().update_still(sigma)


@pytest.fixture
def spy(monkeypatch):
    monkeypatch.setattr(eskf, "_Filter", _Spy)
    return _Spy


def _imu(n=16, spike_at=None):
    """10 Hz, still-looking: accel x and gyro z ramp slowly (each sample its own value), one accel spike."""
    t = np.arange(n) * 0.1
    accel = np.zeros((n, 3))
    accel[:, 0] = 0.01 * np.arange(n)
    accel[:, 2] = GRAVITY
    gyro = np.zeros((n, 3))
    gyro[:, 2] = 0.001 * np.arange(n)
    if spike_at is not None:
        accel[spike_at, 1] = 0.2
    return ImuSamples(t, accel, gyro)


def _mid(imu, i, j):
    return 0.5 * (imu.accel[i] + imu.accel[j]), 0.5 * (imu.gyro[i] + imu.gyro[j])


def _check_log(log, expected):
    """``expected``: tuples as logged; numbers compared to 1e-12, arrays elementwise."""
    assert [e[0] for e in log] == [e[0] for e in expected]
    for got, want in zip(log, expected):
        assert len(got) == len(want), got[0]
        for g, w in zip(got[1:], want[1:]):
            if isinstance(w, (bool, np.bool_, int)) and not isinstance(w, float):
                assert g == w, (got[0], g, w)
            else:
                np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-15, err_msg=got[0])


def _prop(imu, i, dt):
    f, w = _mid(imu, i, min(i + 1, imu.t_s.size - 1))
    return ("propagate", f, w, dt)


def _vo(t, p, ref=None, valid=None, rot=None):
    n = len(t)
    R = np.stack([np.eye(3) if rot is None or rot[k] is None else so3_exp(rot[k]) for k in range(n)])
    cov = np.stack([np.diag([1e-4, 2e-4, 3e-4, 1e-6, 2e-6, 3e-6]) * (k + 1) for k in range(n)])
    return RelativePoses(np.asarray(t, float), R, np.asarray(p, float), cov, valid=valid, ref=ref)


def test_frame_to_frame_with_time_offset_wheel_flat_ground_and_still_spells(spy):
    imu = _imu(spike_at=15)
    # camera times -0.05 (before the IMU: dropped) .. 1.60 (after it: dropped); IMU time = camera + 0.02
    vo = _vo([-0.05, 0.23, 0.47, 0.55, 1.32, 1.60],
             [[0, 0, 0], [0.3, 0, 0], [0.001, 0, 0], [5, 5, 5], [0.002, 0.001, 0], [1, 0, 0]],
             valid=[True, True, True, False, True, True], rot=[None, None, None, None, [0, 0, 0.01], None])
    T = np.eye(4)
    T[:3, :3] = so3_exp([0.0, 0.0, np.pi / 2])
    T[:3, 3] = [0.1, 0.0, 0.05]
    cfg = eskf.EskfConfig(camera_time_offset_s=0.02, imu_T_camera=T, vo_cov_scale=2.0, gate_prob=0.99,
                          wheel_sigma_frac=0.05, wheel_sigma_m=0.002, flat_ground_sigma_m=0.004,
                          zupt_sigma_m_s=0.005, imu_noise=ImuNoise())
    spy.script = [True, True]
    wheel = ([0.0, 0.5, 1.0, 1.5], [0.0, 0.1, 0.3, 0.6])
    res = eskf.fuse(imu, vo, cfg, wheel=wheel)
    flt = spy.last
    gate = chi2.ppf(0.99, 6)

    def rel(k):
        return ("update_relative",) + eskf.camera_to_imu_motion(vo.R[k], vo.p[k], vo.cov[k] * 2.0, T) + (gate,)

    def fwd(a, b):
        d = np.interp(b, *wheel) - np.interp(a, *wheel)
        return ("update_forward", d, 0.05 * d + 0.002)

    H = ("update_height", 0.004)
    expected = [("clone",), _prop(imu, 0, 0.1), _prop(imu, 1, 0.1),
                # frame 1 at 0.25: the first kept frame (no update, no wheel), cloned
                _prop(imu, 2, 0.05), ("node_prior", 0.25, 2), H, ("node_posterior", True, True), ("clone",),
                _prop(imu, 2, 0.05), _prop(imu, 3, 0.1),
                # frame 2 at 0.49: relative to frame 1, the wheel's travel since 0.25
                _prop(imu, 4, 0.09), ("node_prior", 0.49, 4), rel(2), fwd(0.25, 0.49), H,
                ("node_posterior", True, True), ("clone",), _prop(imu, 4, 0.01),
                # its speed 0.001 m / 0.24 s is under zupt_speed_m_s and samples 3..5 are quiet: still at 0.5
                ("node_prior", 0.5, 4), ("update_still", 0.005), ("node_posterior", False, False),
                # frame 3 at 0.57 failed: no update, no more still spells until odometry says so again
                _prop(imu, 5, 0.07), ("node_prior", 0.57, 5), fwd(0.49, 0.57), H, ("node_posterior", True, True),
                ("clone",), _prop(imu, 5, 0.03)]
    expected += [_prop(imu, i, 0.1) for i in range(6, 13)]
    expected += [_prop(imu, 13, 0.04), ("node_prior", 1.34, 13), rel(4), fwd(0.57, 1.34), H,
                 ("node_posterior", True, True), ("clone",), _prop(imu, 13, 0.06),
                 # speed |p_b| / 0.77 s; samples 12..14 quiet: still at 1.4; 13..15 hold the spike: not at 1.5
                 ("node_prior", 1.4, 13), ("update_still", 0.005), ("node_posterior", False, False),
                 _prop(imu, 14, 0.1)]
    _check_log(flt.log, expected)
    np.testing.assert_allclose(res.frame_t_s, [0.25, 0.49, 0.57, 1.34], rtol=0, atol=1e-12)
    assert res.frame_index.tolist() == [3, 5, 6, 14]
    assert res.vo_used.tolist() == [False, True, False, True] and not res.vo_rejected.any()
    np.testing.assert_allclose(res.zupt_t_s, [0.5, 1.4], rtol=0, atol=1e-12)
    assert res.zupt_count == 2
    for k, (p, R, cov) in enumerate(flt.snaps):
        np.testing.assert_array_equal(res.frame_p[k], p)
        np.testing.assert_array_equal(res.frame_R[k], R)
        np.testing.assert_array_equal(res.frame_cov[k], cov)
    # every sample holds the state at its time: the last one the filter's end state, the first the start
    np.testing.assert_array_equal(res.p[-1], flt.p)
    np.testing.assert_array_equal(res.v[-1], flt.v)
    np.testing.assert_array_equal(res.R[-1], flt.R)
    np.testing.assert_array_equal(res.accel_bias[-1], flt.ba)
    np.testing.assert_array_equal(res.gyro_bias[-1], flt.bg)
    assert np.array_equal(res.p[0], np.zeros(3)) and np.array_equal(res.v[0], np.zeros(3))
    np.testing.assert_allclose(res.gyro_bias[0], [0, 0, 0.005], rtol=1e-12)  # the still start's mean rate
    np.testing.assert_array_equal(res.t_s, imu.t_s)
    np.testing.assert_array_equal(res.imu_T_antenna, cfg.imu_T_antenna)


def test_keyframes_reclone_only_when_the_reference_moves_on_and_a_rejection_stops_still_spells(spy):
    imu = _imu(n=12)
    # frames 1-3 refer to keyframe 0, frame 4 to frame 3; IMU time = camera time
    vo = _vo([0.05, 0.25, 0.45, 0.65, 0.85], [[0, 0, 0], [0.5, 0, 0], [0.5008, 0, 0], [0.6, 0, 0], [0.1, 0, 0]],
             ref=[-1, 0, 0, 0, 3])
    cfg = eskf.EskfConfig()
    spy.script = [True, True, False, True]
    res = eskf.fuse(imu, vo, cfg)
    flt = spy.last
    gate = chi2.ppf(0.999, 6)
    I4 = np.eye(4)

    def rel(k):
        return ("update_relative",) + eskf.camera_to_imu_motion(vo.R[k], vo.p[k], vo.cov[k], I4) + (gate,)

    expected = [("clone",), _prop(imu, 0, 0.05), ("node_prior", 0.05, 0), ("node_posterior", True, True),
                ("clone",), _prop(imu, 0, 0.05), _prop(imu, 1, 0.1),
                _prop(imu, 2, 0.05), ("node_prior", 0.25, 2), rel(1), ("node_posterior", False, True),
                _prop(imu, 2, 0.05), _prop(imu, 3, 0.1),
                # frame 2 moved 0.8 mm since frame 1 (both from keyframe 0) in 0.2 s: still
                _prop(imu, 4, 0.05), ("node_prior", 0.45, 4), rel(2), ("node_posterior", False, True),
                _prop(imu, 4, 0.05), ("node_prior", 0.5, 4), ("update_still", 0.003),
                ("node_posterior", False, False),
                # still again at 0.6: the speed holds until the next frame
                _prop(imu, 5, 0.1), ("node_prior", 0.6, 5), ("update_still", 0.003), ("node_posterior", False, False),
                # frame 3 gated out: the speed is unknown, no still spell; frame 4 refers to it: clone there
                _prop(imu, 6, 0.05), ("node_prior", 0.65, 6), rel(3), ("node_posterior", True, True), ("clone",),
                _prop(imu, 6, 0.05), _prop(imu, 7, 0.1),
                # frame 4: 0.1 m in 0.2 s from frame 3, moving; the last frame clones
                _prop(imu, 8, 0.05), ("node_prior", 0.85, 8), rel(4), ("node_posterior", True, True), ("clone",),
                _prop(imu, 8, 0.05), _prop(imu, 9, 0.1), _prop(imu, 10, 0.1)]
    _check_log(flt.log, expected)
    assert res.vo_used.tolist() == [False, True, True, False, True]
    assert res.vo_rejected.tolist() == [False, False, False, True, False]
    assert res.frame_index.tolist() == [1, 3, 5, 7, 9]
    np.testing.assert_allclose(res.zupt_t_s, [0.5, 0.6], rtol=0, atol=1e-12)


def test_imu_alone_only_propagates_and_no_wheel_update_without_frames(spy):
    imu = _imu(n=12)
    res = eskf.fuse(imu, None, eskf.EskfConfig(), wheel=([0.0, 1.1], [0.0, 1.0]))
    _check_log(spy.last.log, [("clone",)] + [_prop(imu, i, 0.1) for i in range(11)])
    assert res.frame_t_s.size == 0 and res.vo_used.size == 0 and res.zupt_count == 0


def test_the_smoother_interpolates_each_node_s_corrections_in_time(spy, monkeypatch):
    imu = _imu(n=12)
    vo = _vo([0.05, 0.25, 0.45, 0.65], [[0, 0, 0], [0.3, 0, 0], [0.001, 0, 0], [0.2, 0, 0]])
    cfg = eskf.EskfConfig()
    spy.script = [True, True, True]
    plain = eskf.fuse(imu, vo, cfg)
    spy.script = [True, True, True]
    rng = np.random.default_rng(4)
    seen = {}

    def fake_rts(nodes):
        seen["nodes"] = nodes
        n = len(nodes)
        xs = [eskf._plus(nd["post"], 0.01 * rng.normal(size=21)) for nd in nodes]
        Ps = [np.diag(rng.uniform(1, 2, 21)) * (k + 1) for k in range(n)]
        eps = [0.01 * rng.normal(size=21) for _ in range(n)]
        dlt = [0.01 * rng.normal(size=21) for _ in range(n)]
        seen.update(xs=xs, Ps=Ps, eps=eps, dlt=dlt)
        return xs, Ps, eps, dlt

    monkeypatch.setattr(eskf, "_rts", fake_rts)
    res = eskf.fuse(imu, vo, cfg, smooth=True)
    nodes = seen["nodes"]
    # nodes at every frame and the two still spells (0.5 and 0.6 s: frame 2 moved 1 mm in 0.2 s)
    tn = [0.05, 0.25, 0.45, 0.5, 0.6, 0.65]
    assert [nd["t"] for nd in nodes] == pytest.approx(tn, abs=1e-12)
    assert [nd["i"] for nd in nodes] == [0, 2, 4, 4, 5, 6]
    assert [nd["frame"] for nd in nodes] == [True, True, True, False, False, True]
    assert [nd["clone"] for nd in nodes] == [True, True, True, False, False, True]
    eps, dlt, xs, Ps = seen["eps"], seen["dlt"], seen["xs"], seen["Ps"]
    for q, t in enumerate(imu.t_s):
        if t < tn[0]:
            d = dlt[0]
        elif t >= tn[-1]:
            d = eps[-1]
        else:
            j = max(k for k in range(len(tn)) if tn[k] <= t)
            w = (t - tn[j]) / (tn[j + 1] - tn[j])
            d = (1 - w) * eps[j] + w * dlt[j + 1]
        want = eskf._plus((plain.p[q], plain.v[q], plain.R[q], plain.accel_bias[q], plain.gyro_bias[q],
                           np.zeros(3), np.eye(3)), d)
        np.testing.assert_allclose(res.p[q], want[0], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(res.v[q], want[1], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(res.R[q], want[2], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(res.accel_bias[q], want[3], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(res.gyro_bias[q], want[4], rtol=1e-12, atol=1e-14)
    # the frames take their nodes' smoothed poses and covariances (the still spell's node is no frame)
    for f, q in enumerate([0, 1, 2, 5]):
        p, R = xs[q][0], xs[q][2]
        np.testing.assert_array_equal(res.frame_p[f], p)
        np.testing.assert_array_equal(res.frame_R[f], R)
        J = np.zeros((6, 6))
        J[:3, :3] = R.T
        J[3:, :3] = -np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])
        J[3:, 3:] = np.eye(3)
        idx = np.r_[6:9, 0:3]
        np.testing.assert_allclose(res.frame_cov[f], J @ Ps[q][np.ix_(idx, idx)] @ J.T, rtol=1e-12, atol=1e-15)


def _linear_chain(rng, coupled: bool, n=5):
    """A linear Gaussian chain in the filter's 21 error states, filtered here into smoother nodes.

    Every nominal attitude is the identity and every mean attitude error zero, so the invariant error is a plain
    difference: ``coupled`` chains (attitude coupled to the rest) carry zero means (the covariances are the
    test), decoupled ones random means. Returns the nodes and the model for the batch solution."""
    m0 = np.zeros(21) if coupled else rng.normal(size=21)
    P0 = _spd(rng, 21)
    Phis = [np.eye(15) + 0.1 * rng.normal(size=(15, 15)) for _ in range(n)]
    Qs = [_spd(rng, 15) * 0.1 for _ in range(n)]
    Hs = [rng.normal(size=(4, 21)) for _ in range(n)]
    Rs = [_spd(rng, 4) * 0.2 for _ in range(n)]
    clones = [bool(c) for c in rng.integers(0, 2, n)]
    th = np.r_[6:9, 18:21]
    if not coupled:
        m0[th] = 0.0
        for M in [P0] + Qs + Phis:
            k = M.shape[0]
            t = th[th < k]
            keep = M[np.ix_(t, t)].copy()
            M[t, :] = 0.0
            M[:, t] = 0.0
            M[np.ix_(t, t)] = keep
        for H in Hs:
            H[:, th] = 0.0
    zs = [np.zeros(4) if coupled else rng.normal(size=4) for _ in range(n)]

    def A(j):  # from node j's posterior to node j+1's prior
        a = np.zeros((21, 21))
        a[:15, :15] = Phis[j + 1]
        if clones[j]:
            a[15:18, 0:3] = np.eye(3)
            a[18:21, 6:9] = np.eye(3)
        else:
            a[15:, 15:] = np.eye(6)
        return a

    def tup(x):
        return (x[0:3].copy(), x[3:6].copy(), np.eye(3), x[9:12].copy(), x[12:15].copy(), x[15:18].copy(),
                np.eye(3))

    nodes, m, P = [], m0, P0
    for j in range(n):
        if j > 0:
            a = A(j - 1)
            m = a @ m
            P = a @ P @ a.T
            P[:15, :15] += Qs[j]
        S = Hs[j] @ P @ Hs[j].T + Rs[j]
        K = P @ Hs[j].T @ np.linalg.inv(S)
        mp = m + K @ (zs[j] - Hs[j] @ m)
        Pp = P - K @ S @ K.T
        nodes.append({"prior": tup(m), "P_prior": P.copy(), "post": tup(mp), "P_post": 0.5 * (Pp + Pp.T),
                      "Phi": Phis[j], "clone": clones[j]})
        m, P = mp, 0.5 * (Pp + Pp.T)
    return nodes, dict(m0=m0, P0=P0, A=A, Qs=Qs, Hs=Hs, Rs=Rs, zs=zs, n=n)


def _spd(rng, k):
    B = rng.normal(size=(k, k))
    return B @ B.T / k + 0.5 * np.eye(k)


def _batch(model):
    """Posterior of every node's state given all measurements: states as linear maps of (x0, w_1..w_n-1)."""
    n = model["n"]
    dim = 21 + 15 * (n - 1)
    L = [np.zeros((21, dim))]
    L[0][:, :21] = np.eye(21)
    for j in range(1, n):
        Lj = model["A"](j - 1) @ L[j - 1]
        Lj[:15, 21 + 15 * (j - 1) : 21 + 15 * j] += np.eye(15)
        L.append(Lj)
    prior_cov = np.zeros((dim, dim))
    prior_cov[:21, :21] = model["P0"]
    for j in range(1, n):
        prior_cov[21 + 15 * (j - 1) : 21 + 15 * j, 21 + 15 * (j - 1) : 21 + 15 * j] = model["Qs"][j]
    mu0 = np.zeros(dim)
    mu0[:21] = model["m0"]
    info = np.linalg.inv(prior_cov)
    vec = info @ mu0
    for j in range(n):
        HL = model["Hs"][j] @ L[j]
        Ri = np.linalg.inv(model["Rs"][j])
        info = info + HL.T @ Ri @ HL
        vec = vec + HL.T @ Ri @ model["zs"][j]
    cov = np.linalg.inv(info)
    mu = cov @ vec
    return [Lj @ mu for Lj in L], [Lj @ cov @ Lj.T for Lj in L]


def _vec(x):
    return np.concatenate([x[0], x[1], np.zeros(3), x[3], x[4], x[5], np.zeros(3)])


@pytest.mark.parametrize("coupled", [True, False])
def test_rts_equals_the_batch_posterior_of_a_linear_chain(coupled):
    rng = np.random.default_rng(11 if coupled else 12)
    nodes, model = _linear_chain(rng, coupled)
    assert any(nd["clone"] for nd in nodes[:-1]) and not all(nd["clone"] for nd in nodes[:-1])
    xs, Ps, eps, dlt = eskf._rts(nodes)
    means, covs = _batch(model)
    for j in range(model["n"]):
        np.testing.assert_allclose(Ps[j], covs[j], rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(_vec(xs[j]), means[j], rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(eps[j], means[j] - _vec(nodes[j]["post"]), rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(dlt[j], means[j] - _vec(nodes[j]["prior"]), rtol=1e-7, atol=1e-9)
        for R in (xs[j][2], xs[j][6]):
            np.testing.assert_allclose(R, np.eye(3), rtol=0, atol=1e-12)
    if not coupled:
        assert np.abs(means[0] - _vec(nodes[0]["post"])).max() > 0.05  # the later data moved the first state
