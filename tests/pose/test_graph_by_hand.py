"""The pose graph by hand: small trajectories whose loop-closed poses follow from the graph's cost written out here
(each edge's residual in the first keyframe's heading frame, over its standard deviation, under a Cauchy loss) and
minimised by a general-purpose optimiser; the correction carried to every pose between keyframes; the gates; the
revisit search on a circle; every message in full.
"""

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.eskf import FusionResult
from gpr3d.pose.graph import GraphConfig, LoopClosure, _wrap, _yaw, close_loops, revisits


def rotz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def straight_run(m=11, speed=0.2, rate=10, heading=0.0, start=(0.0, 0.0)):
    """Frames at 1 Hz from ``start`` along ``heading`` at ``speed`` m/s, 0.1 m up; IMU samples at ``rate`` Hz."""
    t = np.arange(m, dtype=float)
    ti = np.arange((m - 1) * rate + 1) / rate
    n = ti.size
    u = np.array([math.cos(heading), math.sin(heading), 0.0])
    base = np.array([start[0], start[1], 0.1])
    Rh = rotz(heading)
    return FusionResult(t_s=ti, p=base + speed * ti[:, None] * u, v=np.tile(speed * u, (n, 1)),
                        R=np.tile(Rh, (n, 1, 1)), accel_bias=np.zeros((n, 3)), gyro_bias=np.zeros((n, 3)),
                        frame_t_s=t, frame_cov=np.zeros((m, 6, 6)), frame_index=np.arange(m) * rate,
                        frame_p=base + speed * t[:, None] * u, frame_R=np.tile(Rh, (m, 1, 1)), vo_used=np.ones(m, bool),
                        vo_rejected=np.zeros(m, bool), zupt_t_s=np.zeros(0), imu_T_antenna=np.eye(4))


def cauchy(r, f):
    return f * f * np.log1p((r / f) ** 2)


def graph_cost(edges, f, start=(0.0, 0.0, 0.0)):
    """The cost of keyframe poses ``z = (x1, y1, yaw1, x2, y2, yaw2, ...)`` (keyframe 0 held at ``start``: x, y, yaw),
    each edge ``(a, b, d (2,), dyaw, sigma_m, sigma_rad)`` a measured motion of b in a's heading frame."""

    def cost(z):
        P = np.vstack([start, np.reshape(z, (-1, 3))])
        total = 0.0
        for a, b, d, dyaw, st, sr in edges:
            c, s = math.cos(P[a, 2]), math.sin(P[a, 2])
            dx, dy = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1]
            total += cauchy((c * dx + s * dy - d[0]) / st, f) + cauchy((-s * dx + c * dy - d[1]) / st, f)
            total += cauchy(float(_wrap(P[b, 2] - P[a, 2] - dyaw)) / sr, f)
        return total

    return cost


def solve(edges, z0, f=3.0, start=(0.0, 0.0, 0.0)):
    out = minimize(graph_cost(edges, f, start), z0, method="BFGS", options={"gtol": 1e-10, "maxiter": 2000})
    return np.vstack([start, out.x.reshape(-1, 3)])


CFG = GraphConfig()  # 1 % of the step + 0.5 mm a frame, 0.03 deg a frame; keyframes every 5 frames
ST_ODO = math.sqrt(5 * 5e-4 ** 2 + (0.01 * 1.0) ** 2 / 5)  # 5 frames, 1 m between keyframes
SR_ODO = math.sqrt(5) * math.radians(0.03)


def test_a_closure_short_of_the_fused_motion_pulls_the_far_keyframes_back():
    res = straight_run()
    lc = LoopClosure(0, 10, np.eye(3), np.array([1.98, 0.0, 0.0]))
    report = {}
    out = close_loops(res, [lc], CFG, report=report)
    assert report == {"closures": 1, "gated": 0, "rejected": 0, "used": 1}
    edges = [(0, 1, [1.0, 0.0], 0.0, ST_ODO, SR_ODO), (1, 2, [1.0, 0.0], 0.0, ST_ODO, SR_ODO),
             (0, 2, [1.98, 0.0], 0.0, 0.005, math.radians(0.2))]
    P = solve(edges, [1.0, 0, 0, 2.0, 0, 0])
    assert 1.98 < P[2, 0] < 2.0 and P[1, 0] == pytest.approx(P[2, 0] / 2, abs=1e-7)
    np.testing.assert_allclose(out.frame_p[[0, 5, 10], 0], P[:, 0], rtol=0, atol=2e-6)
    np.testing.assert_allclose(out.frame_p[:, 1:], res.frame_p[:, 1:], rtol=0, atol=1e-9)
    # frames and IMU samples between keyframes take their keyframes' shifts, blended by time
    shift = P[:, 0] - [0.0, 1.0, 2.0]
    w = np.interp(res.frame_t_s, [0, 5, 10], [0, 1, 2])
    want = res.frame_p[:, 0] + np.interp(w, [0, 1, 2], shift)
    np.testing.assert_allclose(out.frame_p[:, 0], want, rtol=0, atol=2e-6)
    wi = np.interp(res.t_s, [0, 5, 10], [0, 1, 2])
    np.testing.assert_allclose(out.p[:, 0], res.p[:, 0] + np.interp(wi, [0, 1, 2], shift), rtol=0, atol=2e-6)
    np.testing.assert_allclose(out.p[:, 1:], res.p[:, 1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(out.R, res.R, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out.v, res.v, rtol=0, atol=1e-9)
    # the input is left as it was
    np.testing.assert_array_equal(res.frame_p, straight_run().frame_p)
    np.testing.assert_array_equal(res.p, straight_run().p)


def test_a_closure_between_frames_off_the_keyframes_is_carried_to_them():
    """A closure from frame 1 to frame 9: moved to keyframes 0 and 10 through the fused motion, its deviation kept,
    its standard deviations widened by the two frames it was carried over."""
    res = straight_run()
    lc = LoopClosure(1, 9, np.eye(3), np.array([1.585, 0.0, 0.0]), sigma_m=0.004, sigma_rad=0.003)
    out = close_loops(res, [lc], CFG)
    st = math.hypot(0.004, math.sqrt(2) * 5e-4 * 3)
    sr = math.hypot(0.003, math.sqrt(2) * math.radians(0.03))
    edges = [(0, 1, [1.0, 0.0], 0.0, ST_ODO, SR_ODO), (1, 2, [1.0, 0.0], 0.0, ST_ODO, SR_ODO),
             (0, 2, [1.985, 0.0], 0.0, st, sr)]
    P = solve(edges, [1.0, 0, 0, 2.0, 0, 0])
    np.testing.assert_allclose(out.frame_p[[0, 5, 10], 0], P[:, 0], rtol=0, atol=2e-6)


def test_a_closure_that_turns_the_far_keyframe_by_hand():
    """A closure that says the last keyframe is 0.1 m to the left and turned 0.2 deg: positions and headings of
    both keyframes from the cost minimised here; each pose between turned about z by its keyframes' blended turn."""
    res = straight_run()
    a = math.radians(0.2)
    lc = LoopClosure(0, 10, rotz(a), np.array([2.0, 0.01, 0.0]))
    out = close_loops(res, [lc], CFG)
    edges = [(0, 1, [1.0, 0.0], 0.0, ST_ODO, SR_ODO), (1, 2, [1.0, 0.0], 0.0, ST_ODO, SR_ODO),
             (0, 2, [2.0, 0.01], a, 0.005, math.radians(0.2))]
    P = solve(edges, [1.0, 0, 0, 2.0, 0, 0])
    assert P[2, 1] > 0.001 and P[2, 2] > 0.0005  # it did move and turn
    np.testing.assert_allclose(out.frame_p[[0, 5, 10], :2], P[:, :2], rtol=0, atol=2e-6)
    np.testing.assert_allclose(_yaw(out.frame_R[[0, 5, 10]]), P[:, 2], rtol=0, atol=2e-7)
    # frame 7: 40 % of the way from keyframe 1 to 2: each keyframe's planar motion applied to it, then blended
    f, p7 = 0.4, res.frame_p[7]
    moved = []
    for k, kf in ((1, 5), (2, 10)):
        moved.append(rotz(P[k, 2]) @ (p7 - res.frame_p[kf]) + res.frame_p[kf] + [P[k, 0] - res.frame_p[kf, 0],
                                                                                    P[k, 1], 0.0])
    np.testing.assert_allclose(out.frame_p[7], (1 - f) * moved[0] + f * moved[1], rtol=0, atol=2e-6)
    np.testing.assert_allclose(out.frame_R[7], rotz((1 - f) * P[1, 2] + f * P[2, 2]), rtol=0, atol=2e-7)
    # IMU sample 73 (t = 7.3 s): 46 % of the way, its velocity turned with it
    g = 0.46
    yaw = (1 - g) * P[1, 2] + g * P[2, 2]
    np.testing.assert_allclose(out.R[73], rotz(yaw), rtol=0, atol=2e-7)
    np.testing.assert_allclose(out.v[73], rotz(yaw) @ res.v[73], rtol=0, atol=1e-7)
    assert out.p[73, 2] == res.p[73, 2]


def test_a_run_heading_north_east_by_hand():
    """The same graph on a run that starts at (1, -2) heading 0.7 rad at 0.15 m/s (0.75 m between keyframes): each
    edge is measured in its first keyframe's heading frame; keyframe 0 is held where it was."""
    res = straight_run(speed=0.15, heading=0.7, start=(1.0, -2.0))
    lc = LoopClosure(0, 10, rotz(0.003), np.array([1.488, 0.008, 0.0]))
    report = {}
    out = close_loops(res, [lc], CFG, report=report)
    assert report["used"] == 1
    st = math.sqrt(5 * 5e-4 ** 2 + (0.01 * 0.75) ** 2 / 5)
    edges = [(0, 1, [0.75, 0.0], 0.0, st, SR_ODO), (1, 2, [0.75, 0.0], 0.0, st, SR_ODO),
             (0, 2, [1.488, 0.008], 0.003, 0.005, math.radians(0.2))]
    kf = res.frame_p[[0, 5, 10]]
    z0 = np.c_[kf[1:, :2], [0.7, 0.7]].ravel()
    P = solve(edges, z0, start=(1.0, -2.0, 0.7))
    np.testing.assert_allclose(out.frame_p[[0, 5, 10], :2], P[:, :2], rtol=0, atol=2e-6)
    np.testing.assert_allclose(_yaw(out.frame_R[[0, 5, 10]]), P[:, 2], rtol=0, atol=2e-7)
    assert abs(P[2, 2] - 0.7) > 1e-4 and np.linalg.norm(P[2, :2] - kf[2, :2]) > 1e-3
    # frame 3: 60 % of the way from keyframe 0 (held) to keyframe 1, each keyframe's planar motion applied
    f, p3 = 0.6, res.frame_p[3]
    moved = [rotz(P[k, 2] - 0.7) @ (p3 - kf[k]) + kf[k] + [P[k, 0] - kf[k, 0], P[k, 1] - kf[k, 1], 0.0]
             for k in (0, 1)]
    np.testing.assert_allclose(out.frame_p[3], (1 - f) * moved[0] + f * moved[1], rtol=0, atol=2e-6)
    np.testing.assert_allclose(out.frame_R[3], rotz(0.7 + f * (P[1, 2] - 0.7)), rtol=0, atol=2e-7)
    # IMU sample 35 (3.5 s): 70 % of the way; its velocity turned by the blended turn
    np.testing.assert_allclose(out.v[35], rotz(0.7 * (P[1, 2] - 0.7)) @ res.v[35], rtol=0, atol=5e-8)


def test_a_closure_that_the_solution_leaves_far_off_is_dropped_and_the_graph_solved_again():
    """Two closures over the same keyframes: a sharp one (1 mm) 5 mm short, and one 3 cm to the right. Both pass the
    gate, but the second stays more than 5 sigmas off the solution: it is dropped, and the result is the graph
    with the first alone."""
    res = straight_run()
    good = LoopClosure(0, 10, np.eye(3), np.array([1.995, 0.0, 0.0]), sigma_m=0.001)
    wrong = LoopClosure(0, 10, np.eye(3), np.array([1.995, -0.03, 0.0]))
    report = {}
    out = close_loops(res, [good, wrong], CFG, report=report)
    assert report == {"closures": 2, "gated": 0, "rejected": 1, "used": 1}
    edges = [(0, 1, [1.0, 0.0], 0.0, ST_ODO, SR_ODO), (1, 2, [1.0, 0.0], 0.0, ST_ODO, SR_ODO),
             (0, 2, [1.995, 0.0], 0.0, 0.001, math.radians(0.2))]
    P = solve(edges, [1.0, 0, 0, 2.0, 0, 0])
    np.testing.assert_allclose(out.frame_p[[0, 5, 10], :2], P[:, :2], rtol=0, atol=2e-6)
    # the order does not matter, and without the wrong one nothing is rejected
    report2 = {}
    out2 = close_loops(res, [wrong, good], CFG, report=report2)
    assert report2 == report
    np.testing.assert_allclose(out2.frame_p, out.frame_p, rtol=0, atol=2e-6)
    report3 = {}
    close_loops(res, [good], CFG, report=report3)
    assert report3["rejected"] == 0


def test_a_closure_from_a_frame_before_a_keyframe_turned():
    """Frame 4 to frame 10 (keyframe 2): carried to keyframe 1 (frame 5) through the fused step back from 5 to 4:
    measured 1.195 m on and 4 mm left, turned 0.002 rad, so keyframe 2 lies (0.995, 0.004) from keyframe 1; one
    frame carried: sigmas widened by one frame's odometry error."""
    res = straight_run()
    lc = LoopClosure(4, 10, rotz(0.002), np.array([1.195, 0.004, 0.0]))
    report = {}
    out = close_loops(res, [LoopClosure(1, 2, np.eye(3), np.array([0.2, 0.0, 0.0])), lc], CFG, report=report)
    assert report == {"closures": 2, "gated": 0, "rejected": 0, "used": 1}  # the first lies within one keyframe
    st = math.hypot(0.005, 5e-4 * 3)
    sr = math.hypot(math.radians(0.2), math.radians(0.03))
    edges = [(0, 1, [1.0, 0.0], 0.0, ST_ODO, SR_ODO), (1, 2, [1.0, 0.0], 0.0, ST_ODO, SR_ODO),
             (1, 2, [0.995, 0.004], 0.002, st, sr)]
    P = solve(edges, [1.0, 0, 0, 2.0, 0, 0])
    np.testing.assert_allclose(out.frame_p[[0, 5, 10], :2], P[:, :2], rtol=0, atol=2e-6)
    np.testing.assert_allclose(_yaw(out.frame_R[[0, 5, 10]]), P[:, 2], rtol=0, atol=2e-7)
    assert P[2, 1] > 1e-4 and P[2, 2] > 1e-4


def test_keyframes_every_four_frames_end_on_the_last():
    res = straight_run()
    lc = LoopClosure(0, 10, np.eye(3), np.array([1.99, 0.003, 0.0]))
    out = close_loops(res, [lc], GraphConfig(keyframe_every=4))
    st4 = math.sqrt(4 * 5e-4 ** 2 + (0.01 * 0.8) ** 2 / 4)
    st2 = math.sqrt(2 * 5e-4 ** 2 + (0.01 * 0.4) ** 2 / 2)
    r4, r2 = 2 * math.radians(0.03), math.sqrt(2) * math.radians(0.03)
    edges = [(0, 1, [0.8, 0.0], 0.0, st4, r4), (1, 2, [0.8, 0.0], 0.0, st4, r4), (2, 3, [0.4, 0.0], 0.0, st2, r2),
             (0, 3, [1.99, 0.003], 0.0, 0.005, math.radians(0.2))]
    P = solve(edges, [0.8, 0, 0, 1.6, 0, 0, 2.0, 0, 0])
    np.testing.assert_allclose(out.frame_p[[0, 4, 8, 10], :2], P[:, :2], rtol=0, atol=2e-6)


def test_two_frames_are_enough():
    res = straight_run(m=2)
    out = close_loops(res, [LoopClosure(0, 1, np.eye(3), np.array([0.199, 0.0, 0.0]))], CFG)
    st = math.sqrt(5e-4 ** 2 + (0.01 * 0.2) ** 2)
    P = solve([(0, 1, [0.2, 0.0], 0.0, st, math.radians(0.03)), (0, 1, [0.199, 0.0], 0.0, 0.005, math.radians(0.2))],
              [0.2, 0, 0])
    np.testing.assert_allclose(out.frame_p[:, :2], P[:, :2], rtol=0, atol=2e-6)
    # a closure may run backwards in time
    back = close_loops(straight_run(), [LoopClosure(10, 0, np.eye(3), np.array([-1.99, 0.0, 0.0]))], CFG)
    assert back.frame_p[10, 0] < 1.999


def test_a_closure_far_from_the_fused_motion_is_gated_out():
    res = straight_run()
    report = {}
    far = LoopClosure(0, 10, np.eye(3), np.array([1.9, 0.0, 0.0]))  # 10 cm: far past what 10 frames can drift
    turned = LoopClosure(0, 10, rotz(math.radians(5)), np.array([2.0, 0.0, 0.0]))
    near = LoopClosure(0, 5, np.eye(3), np.array([1.0, 0.0, 0.0]))
    out = close_loops(res, [far, turned, near], CFG, report=report)
    assert report == {"closures": 3, "gated": 2, "rejected": 0, "used": 1}
    np.testing.assert_allclose(out.frame_p, res.frame_p, rtol=0, atol=1e-7)


@pytest.mark.parametrize("i, j", [(0, 10), (5, 10)])
def test_the_gate_is_the_drift_the_odometry_can_explain(i, j):
    """Var = the frames between of 0.5 mm, 1 % of each 0.2 m step, the heading's drift over the distance, and the
    closure's own: a closure short by 3.7 sigma passes (13.7 < 13.8), by 3.72 sigma is gated. Between keyframes 1
    and 2 only their own five frames count."""
    res = straight_run()
    n, length = j - i, 0.2 * (j - i)
    var = n * 5e-4 ** 2 + n * (0.01 * 0.2) ** 2 + n * math.radians(0.03) ** 2 * length ** 2 + 0.005 ** 2
    for k, gated in ((3.70, 0), (3.72, 1)):
        report = {}
        close_loops(res, [LoopClosure(i, j, np.eye(3), np.array([length - k * math.sqrt(var), 0, 0]))], CFG,
                    report=report)
        assert report["gated"] == gated, k
    # the heading gate: 10.8 against the drift and the closure's own
    var_r = n * math.radians(0.03) ** 2 + math.radians(0.2) ** 2
    for k, gated in ((3.28, 0), (3.3, 1)):
        report = {}
        close_loops(res, [LoopClosure(i, j, rotz(k * math.sqrt(var_r)), np.array([length, 0, 0]))], CFG,
                    report=report)
        assert report["gated"] == gated, k


def test_a_closure_within_one_keyframe_is_skipped_and_the_start_is_held():
    res = straight_run()
    report = {}
    out = close_loops(res, [LoopClosure(1, 2, np.eye(3), np.array([0.3, 0.0, 0.0]))], CFG, report=report)
    assert report == {"closures": 1, "gated": 0, "rejected": 0, "used": 0}
    np.testing.assert_allclose(out.frame_p, res.frame_p, rtol=0, atol=1e-9)
    # the last frame is always a keyframe (11 frames, every 4: 0, 4, 8, 10)
    lc = LoopClosure(0, 10, np.eye(3), np.array([1.99, 0.0, 0.0]))
    out = close_loops(res, [lc], GraphConfig(keyframe_every=4))
    assert out.frame_p[10, 0] < 1.999 and out.frame_p[0, 0] == res.frame_p[0, 0]


def test_messages_in_full():
    res = straight_run()
    with pytest.raises(InvalidDataError) as err:
        close_loops(res, [LoopClosure(0, 11, np.eye(3), np.zeros(3))])
    assert str(err.value) == "loop closure (0, 11) names frames outside 0..10 or one frame twice"
    for bad in ((-1, 3), (4, 4)):
        with pytest.raises(InvalidDataError) as err:
            close_loops(res, [LoopClosure(*bad, np.eye(3), np.zeros(3))])
        assert str(err.value) == f"loop closure ({bad[0]}, {bad[1]}) names frames outside 0..10 or one frame twice"
    one = straight_run(m=1)
    with pytest.raises(InvalidDataError) as err:
        close_loops(one, [])
    assert str(err.value) == "loop closing needs a fused trajectory with at least two frames"
    assert close_loops(res, []) is res
    for name in ("trans_frac", "trans_floor_m", "rot_deg", "loss_scale"):
        for v in (0.0, -1.0, float("nan"), float("inf")):
            with pytest.raises(InvalidDataError) as err:
                GraphConfig(**{name: v})
            assert str(err.value) == f"{name} must be a positive number, got {v!r}"
    for v in (0, 2.5):
        with pytest.raises(InvalidDataError) as err:
            GraphConfig(keyframe_every=v)
        assert str(err.value) == f"keyframe_every must be a whole number >= 1, got {v!r}"
    assert GraphConfig(keyframe_every=1).keyframe_every == 1
    with pytest.raises(InvalidDataError) as err:
        close_loops(res, [LoopClosure(11, 3, np.eye(3), np.zeros(3))])
    assert str(err.value) == "loop closure (11, 3) names frames outside 0..10 or one frame twice"
    g = GraphConfig()
    assert (g.trans_frac, g.trans_floor_m, g.rot_deg, g.keyframe_every, g.loss_scale) == (0.01, 5e-4, 0.03, 5, 3.0)
    lc = LoopClosure(0, 1, np.eye(3), np.zeros(3))
    assert lc.sigma_m == 0.005 and lc.sigma_rad == pytest.approx(math.radians(0.2), rel=1e-15)


# ------------------------------------------------------------------------------------------------ revisits

def circle(n_laps=2.0, period=20.0, rate=1.0, radius=1.0):
    """A cart going round a circle (anticlockwise, heading along the tangent)."""
    t = np.arange(0, n_laps * period, 1 / rate)
    ang = 2 * np.pi * t / period
    p = np.c_[radius * np.cos(ang), radius * np.sin(ang), np.zeros(t.size)]
    R = np.stack([rotz(a + np.pi / 2) for a in ang])
    return t, p, R


def test_revisits_on_a_circle_pair_each_frame_with_the_same_place_a_lap_before():
    t, p, R = circle()
    assert revisits(t, p, R) == [(b - 20, b) for b in range(20, 40)]
    # every 2 s: every second frame
    assert revisits(t, p, R, every_s=2.0) == [(b - 20, b) for b in range(20, 40, 2)]
    # a radius smaller than the distance: still the same place (distance 0); a gap longer than a lap: none
    assert revisits(t, p, R, radius_m=1e-6) == [(b - 20, b) for b in range(20, 40)]
    assert revisits(t, p, R, min_gap_s=20.0) == []
    assert revisits(t, p, R, min_gap_s=19.5) == [(b - 20, b) for b in range(20, 40)]


def test_revisits_take_the_nearest_view_within_the_radius_and_angle():
    t, p, R = circle()
    # the second lap 0.3 m further out: its views lie near the first lap's, not on them
    p2 = p.copy()
    p2[20:, :2] *= 1.3
    look1 = p[:20, :2] + 0.8 * R[:20, :2, 0]
    look2 = p2[20:, :2] + 0.8 * R[20:, :2, 0]
    want = []
    for b in range(20):
        d = np.linalg.norm(look1 - look2[b], axis=1)
        ok = d < 0.4
        if ok.any():
            want.append((int(np.flatnonzero(ok)[np.argmin(d[ok])]), b + 20))
    assert want and len(want) == 20
    assert revisits(t, p2, R) == want
    assert revisits(t, p2, R, radius_m=0.25) == []  # 0.3 m apart at their nearest


@pytest.mark.parametrize("turn_deg, max_angle, radius, found", [(40, 45, 1.0, True), (50, 45, 1.0, False),
                                                                (50, 55, 1.0, True), (40, 45, 0.5, False),
                                                                (-40, 45, 1.0, True), (0, 45, 1e-3, True)])
def test_revisits_gate_on_the_heading_and_the_view(turn_deg, max_angle, radius, found):
    """The same spot 20 s later, turned: the views 0.8 m ahead lie 1.6 sin(turn / 2) apart (0.547 m at 40 deg)."""
    t = np.array([0.0, 10.0, 20.0])
    p = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 0.0], [0.0, 0.0, 0.0]])
    R = np.stack([np.eye(3), np.eye(3), rotz(math.radians(turn_deg))])
    assert revisits(t, p, R, radius_m=radius, max_angle_deg=max_angle) == ([(0, 2)] if found else [])


def test_revisits_defaults_and_edges():
    """Defaults: views within 0.4 m, headings within 45 deg, 15 s apart; two frames are enough; the view lies 0.8 m
    ahead (a cart that comes back from the side sees the same ground)."""
    def pair(t2, turn_deg, p2=(0.0, 0.0), **kw):
        t = np.array([0.0, t2])
        p = np.array([[0.0, 0.0, 0.0], [p2[0], p2[1], 0.0]])
        return revisits(t, p, np.stack([np.eye(3), rotz(math.radians(turn_deg))]), **kw)

    assert pair(15.5, 0.0) == [(0, 1)] and pair(14.5, 0.0) == []
    assert pair(20.0, 45.5, radius_m=1.0) == [] and pair(20.0, 44.5, radius_m=1.0) == [(0, 1)]
    # coming back turned 30 deg from a spot chosen so that its view 0.8 m ahead is the first one's
    c, s_ = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert pair(20.0, 30.0, p2=(0.8 - 0.8 * c, -0.8 * s_), radius_m=0.05) == [(0, 1)]
    # exactly at the radius: out (0.5 m: the view from (0.5, 0) is (1.3, 0))
    assert pair(20.0, 0.0, p2=(0.5, 0.0), radius_m=0.5) == []
    assert pair(20.0, 0.0, p2=(0.5, 0.0), radius_m=0.5000001) == [(0, 1)]


def test_revisits_need_two_frames_and_positive_settings():
    t, p, R = circle()
    assert revisits(t[:1], p[:1], R[:1]) == []
    for name in ("every_s", "radius_m", "max_angle_deg"):
        for v in (0.0, -2.0, float("nan")):
            with pytest.raises(InvalidDataError) as err:
                revisits(t, p, R, **{name: v})
            assert str(err.value) == f"{name} must be a positive number, got {v!r}"


def test_yaw_and_wrap_by_hand():
    assert _yaw(rotz(0.3)) == pytest.approx(0.3, rel=1e-15)
    np.testing.assert_allclose(_yaw(np.stack([rotz(-2.0), rotz(3.0)])), [-2.0, 3.0], rtol=1e-15)
    np.testing.assert_allclose(_wrap([3 * np.pi / 2, -3 * np.pi / 2, 0.5, np.pi, -np.pi, 7.0]),
                               [-np.pi / 2, np.pi / 2, 0.5, -np.pi, -np.pi, 7.0 - 2 * np.pi], rtol=0, atol=1e-12)
