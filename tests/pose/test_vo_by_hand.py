"""Visual odometry's bookkeeping by hand, with a recording stand-in for Open3D that answers each registration from a
script (the camera creeping 3 cm a frame along x): which frame each one is registered to and from which guess,
when the keyframe moves on, why a registration is marked lost, the covariance, the report, how frames are handed to
Open3D, the texture measure on hand-made pictures, loop closures from registrations, and every message in full.
"""

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from gpr3d.core.camera import CameraIntrinsics
from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.pose import vo
from gpr3d.pose.vo import OdometryConfig, rgbd_loop_closures, rgbd_odometry, texture_share

INTR = CameraIntrinsics(8, 6, 5.0, 5.5, 3.5, 2.5)
N_PIX = 48
STEP = 0.03  # m a frame


def moved(x=0.0, yaw=0.0):
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[0, 3] = x
    return T


class FakeOpen3D:
    """Open3D's calls that odometry makes, recorded; ``answer(i, j, init)`` gives each registration's result."""

    def __init__(self, answer):
        self.answer, self.calls, self.images = answer, [], []
        self.camera = SimpleNamespace(PinholeCameraIntrinsic=lambda *a: ("pinhole",) + a)
        self.utility = SimpleNamespace(IntVector=lambda xs: ("IntVector", tuple(xs)))
        self.geometry = SimpleNamespace(Image=lambda a: a, RGBDImage=SimpleNamespace(create_from_color_and_depth=self.rgbd))
        self.pipelines = SimpleNamespace(odometry=SimpleNamespace(
            OdometryOption=lambda: SimpleNamespace(), RGBDOdometryJacobianFromHybridTerm=lambda: "hybrid",
            compute_rgbd_odometry=self.register))

    def rgbd(self, colour, depth, **kw):
        img = {"frame": int(depth.flat[0]) - 1000, "colour": colour, "depth": depth, **kw}
        self.images.append(img)
        return img

    def register(self, src, dst, pin, init, jac, opt):
        self.calls.append({"i": src["frame"], "j": dst["frame"], "init": init.copy(), "pin": pin, "jac": jac,
                           "opt": opt})
        return self.answer(src["frame"], dst["frame"], init)


def creep(i, j, init, info=None):
    """The camera moved STEP a frame along x: frame j in frame i is moved((j - i) STEP); Open3D returns its
    inverse (it maps the keyframe's points into the frame)."""
    return True, np.linalg.inv(moved((j - i) * STEP)), np.diag([1e4, 2e4, 3e4, 4e4, 5e4, 6e4]) if info is None else info


def frames(n, textured=True, plain=(), seed=0):
    rng = np.random.default_rng(seed)
    for k in range(n):
        colour = (rng.integers(0, 255, (6, 8, 3)) if textured and k not in plain else np.full((6, 8, 3), 90))
        depth = np.full((6, 8), 1500, np.uint16)
        depth.flat[0] = 1000 + k  # the frame's number, for the stand-in
        yield k / 15.0, colour.astype(np.uint8), depth


@pytest.fixture
def fake(monkeypatch):
    def install(answer=creep):
        o3d = FakeOpen3D(answer)
        monkeypatch.setattr(vo, "require_open3d", lambda: o3d)
        return o3d

    return install


def test_frames_go_to_the_keyframe_from_the_carried_on_motion(fake):
    o3d = fake()
    done = []
    rel, report = rgbd_odometry(frames(10), INTR, OdometryConfig(), progress=done.append)
    # 3 cm a frame, a new keyframe past 10 cm: frames 1-4 to frame 0, 5-8 to frame 4, 9 to frame 8
    assert [(c["i"], c["j"]) for c in o3d.calls] == [(0, 1), (0, 2), (0, 3), (0, 4), (4, 5), (4, 6), (4, 7), (4, 8),
                                                      (8, 9)]
    np.testing.assert_array_equal(rel.ref, [-1, 0, 0, 0, 0, 4, 4, 4, 4, 8])
    # the guess: the last motion from the keyframe carried one frame on (the first from rest)
    guesses = [np.linalg.inv(c["init"])[0, 3] for c in o3d.calls]
    np.testing.assert_allclose(guesses, [0, 0.06, 0.09, 0.12, 0.03, 0.06, 0.09, 0.12, 0.03], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rel.p[:, 0], [0, 0.03, 0.06, 0.09, 0.12, 0.03, 0.06, 0.09, 0.12, 0.03], atol=1e-12)
    np.testing.assert_allclose(rel.R, np.tile(np.eye(3), (10, 1, 1)), atol=1e-12)
    np.testing.assert_array_equal(rel.valid, [False] + [True] * 9)
    np.testing.assert_allclose(rel.t_s, np.arange(10) / 15.0, rtol=0, atol=0)
    info = np.diag([1e4, 2e4, 3e4, 4e4, 5e4, 6e4])
    np.testing.assert_allclose(rel.cov[3], 0.012 * np.linalg.inv(info), rtol=1e-12)
    np.testing.assert_array_equal(rel.cov[0], np.eye(6))
    assert done == list(range(1, 10))
    assert report["frames"] == 10 and report["keyframes"] == 3 and report["registered"] == 9
    assert report["lost"] == {} and 0 <= report["s_per_frame"] < 1


def test_frame_to_frame_and_turns_move_the_keyframe_on(fake):
    o3d = fake()
    rel, report = rgbd_odometry(frames(4), INTR, OdometryConfig(keyframe_m=0.0))
    assert [(c["i"], c["j"]) for c in o3d.calls] == [(0, 1), (1, 2), (2, 3)] and report["keyframes"] == 4
    np.testing.assert_array_equal(rel.ref, [-1, 0, 1, 2])
    # a turn of 2 deg a frame: past 5 deg after three frames
    M = moved(0.001, math.radians(2))
    o3d = fake(lambda i, j, init: (True, np.linalg.inv(np.linalg.matrix_power(M, j - i)), np.eye(6) * 1e4))
    rel, report = rgbd_odometry(frames(6), INTR, OdometryConfig())
    np.testing.assert_array_equal(rel.ref, [-1, 0, 0, 0, 3, 3])
    assert report["keyframes"] == 2
    np.testing.assert_allclose(np.linalg.inv(o3d.calls[2]["init"]), np.linalg.matrix_power(M, 3), atol=1e-12)
    # exactly on the thresholds: not past them
    o3d = fake(lambda i, j, init: (True, np.linalg.inv(moved(0.05 * (j - i))), np.eye(6) * 1e4))
    rel, _ = rgbd_odometry(frames(5), INTR, OdometryConfig(keyframe_m=0.1))
    np.testing.assert_array_equal(rel.ref, [-1, 0, 0, 0, 3])  # frame 2 lies 0.1 m on: still on keyframe 0


def test_lost_frames_and_their_reasons(fake):
    """Frame 3: Open3D fails; frame 6: a motion of 1 m in 1/15 s; frame 8: a degenerate information; frame 10 and
    11 plain (no texture): each lost frame becomes the keyframe and tracking restarts from rest."""
    def answer(i, j, init):
        if j == 3:
            return False, np.eye(4), np.zeros((6, 6))
        if j == 6:
            return True, np.linalg.inv(moved(1.0)), np.eye(6) * 1e4
        if j == 8:
            return True, np.linalg.inv(moved(STEP * (j - i))), np.diag([0.1, 1e4, 1e4, 1e4, 1e4, 1e4])
        return creep(i, j, init)

    o3d = fake(answer)
    rel, report = rgbd_odometry(frames(13, plain=(10,)), INTR, OdometryConfig())
    np.testing.assert_array_equal(rel.valid, [False, True, True, False, True, True, False, True, False, True, False,
                                              False, True])
    # frame 7 is registered to 6 (the lost frame, now the keyframe) and keeps it; 8 is lost against 6; the plain
    # frame 10 is lost against 8, and 11 against the plain 10
    np.testing.assert_array_equal(rel.ref, [-1, 0, 0, 0, 3, 3, 3, 6, 6, 8, 8, 10, 11])
    assert report["lost"] == {"open3d failed": 1, "implausible motion": 1, "degenerate information": 1,
                              "too little texture": 2}
    assert report["registered"] == 7 and report["frames"] == 13
    for k in (3, 6, 8, 10, 11):
        np.testing.assert_array_equal(rel.R[k], np.eye(3))
        np.testing.assert_array_equal(rel.p[k], np.zeros(3))
        np.testing.assert_array_equal(rel.cov[k], np.eye(6))
    # after a lost frame the guess starts from rest
    inits = {(c["i"], c["j"]): np.linalg.inv(c["init"])[0, 3] for c in o3d.calls}
    assert inits[(3, 4)] == 0.0 and inits[(6, 7)] == 0.0 and inits[(8, 9)] == 0.0 and inits[(10, 11)] == 0.0
    assert inits[(3, 5)] == pytest.approx(0.06, abs=1e-12) and inits[(6, 8)] == pytest.approx(0.06, abs=1e-12)


def test_implausible_turns_and_infinite_answers_are_lost(fake):
    fake(lambda i, j, init: (True, np.linalg.inv(moved(0.0, 0.25)), np.eye(6) * 1e4))  # 3.75 rad/s
    _, report = rgbd_odometry(frames(2), INTR, OdometryConfig())
    assert report["lost"] == {"implausible motion": 1}
    _, report = rgbd_odometry(frames(2), INTR, OdometryConfig(max_turn_rad_s=4.0))
    assert report["lost"] == {}
    fake(lambda i, j, init: (True, np.linalg.inv(moved(2.0 / 15 - 1e-9)), np.eye(6) * 1e4))  # just under 2 m/s
    _, report = rgbd_odometry(frames(2), INTR, OdometryConfig())
    assert report["lost"] == {}
    bad = np.eye(4)
    bad[0, 3] = np.nan
    fake(lambda i, j, init: (True, bad, np.eye(6) * 1e4))
    _, report = rgbd_odometry(frames(2), INTR, OdometryConfig())
    assert report["lost"] == {"open3d failed": 1}
    # the information's smallest eigenvalue against min_information per pixel: 0.01 x 48 = 0.48
    for low, lost in ((0.47, {"degenerate information": 1}), (0.49, {})):
        fake(lambda i, j, init: creep(i, j, init, np.diag([low, 1e4, 1e4, 1e4, 1e4, 1e4])))
        assert rgbd_odometry(frames(2), INTR, OdometryConfig())[1]["lost"] == lost


def test_the_covariance_is_the_scaled_inverse_of_the_symmetrised_information(fake):
    info = np.diag([1e4, 2e4, 3e4, 4e4, 5e4, 6e4])
    info[0, 1], info[1, 0] = 3e3, 1e3  # a little asymmetric, as a solver may return it
    fake(lambda i, j, init: creep(i, j, init, info))
    rel, _ = rgbd_odometry(frames(2), INTR, OdometryConfig(cov_scale=0.5))
    np.testing.assert_allclose(rel.cov[1], 0.5 * np.linalg.inv(0.5 * (info + info.T)), rtol=1e-12)


def test_frames_are_handed_to_open3d_as_it_wants_them(fake):
    o3d = fake()
    gray = np.full((6, 8), 70.0)
    depth = np.full((6, 8), 1.5)
    depth[0, 0] = 1000.0  # frame 0
    depth[2, 3] = np.nan
    depth2 = np.full((6, 8), 1500, np.int32)
    depth2[0, 0] = 1001
    cfg = OdometryConfig(min_texture=0.0, depth_scale=1.0, depth_max_m=2.5, depth_min_m=0.3, depth_diff_max_m=0.05,
                         iterations=(7, 3))
    rgbd_odometry([(0.0, gray, depth), (0.1, np.zeros((6, 8, 3), np.float64), depth2)], INTR, cfg)
    a, b = o3d.images
    assert a["colour"].dtype == np.uint8 and a["colour"].shape == (6, 8, 3) and (a["colour"] == 70).all()
    assert a["depth"].dtype == np.float32 and a["depth"][2, 3] == 0 and a["depth"][1, 1] == np.float32(1.5)
    assert b["colour"].dtype == np.uint8 and b["depth"].dtype == np.uint16 and b["depth"][0, 0] == 1001
    for img in (a, b):
        assert img["colour"].flags.c_contiguous and img["depth"].flags.c_contiguous
        assert (img["depth_scale"], img["depth_trunc"], img["convert_rgb_to_intensity"]) == (1.0, 2.5, True)
    (call,) = o3d.calls
    assert call["pin"] == ("pinhole", 8, 6, 5.0, 5.5, 3.5, 2.5) and call["jac"] == "hybrid"
    opt = call["opt"]
    assert opt.iteration_number_per_pyramid_level == ("IntVector", (7, 3))
    assert (opt.depth_diff_max, opt.depth_min, opt.depth_max) == (0.05, 0.3, 2.5)


def test_bad_frames_are_named_in_full(fake):
    fake()
    good = list(frames(3))

    def run(items):
        with pytest.raises(InvalidDataError) as err:
            rgbd_odometry(items, INTR, OdometryConfig())
        return str(err.value)

    assert run([good[0], (0.0, good[1][1], good[1][2])]) == "frame 1: its time 0.0 does not increase"
    assert run([good[0], (float("nan"), good[1][1], good[1][2])]) == "frame 1: its time nan does not increase"
    assert run([(float("inf"),) + good[0][1:]]) == "frame 0: its time inf does not increase"
    assert run([good[0], (0.2, good[1][1][:5], good[1][2])]) == (
        "frame 1: colour (5, 8, 3) / depth (6, 8) do not match the 8 x 6 camera")
    assert run([good[0], (0.2, good[1][1], good[1][2][:, :7])]) == (
        "frame 1: colour (6, 8, 3) / depth (6, 7) do not match the 8 x 6 camera")
    assert run([good[0], (0.2, good[1][1][..., :2], good[1][2])]) == "frame 1: colour must be h x w x 3 or h x w, " \
                                                                     "got (6, 8, 2)"
    assert run(good[:1]) == "odometry needs at least two frames, got 1"
    assert run([]) == "odometry needs at least two frames, got 0"


@pytest.mark.parametrize("kw, msg", [
    ({"keyframe_m": -0.1}, "keyframe_m must be 0 (frame to frame) or positive, got -0.1"),
    ({"keyframe_m": float("nan")}, "keyframe_m must be 0 (frame to frame) or positive, got nan"),
    ({"depth_scale": 0.0}, "depth_scale must be a positive number, got 0.0"),
    ({"depth_max_m": float("inf")}, "depth_max_m must be a positive number, got inf"),
    ({"depth_diff_max_m": -1.0}, "depth_diff_max_m must be a positive number, got -1.0"),
    ({"max_speed_m_s": 0.0}, "max_speed_m_s must be a positive number, got 0.0"),
    ({"max_turn_rad_s": 0.0}, "max_turn_rad_s must be a positive number, got 0.0"),
    ({"min_information": 0.0}, "min_information must be a positive number, got 0.0"),
    ({"texture_gradient": 0.0}, "texture_gradient must be a positive number, got 0.0"),
    ({"cov_scale": float("nan")}, "cov_scale must be a positive number, got nan"),
    ({"keyframe_deg": 0.0}, "keyframe_deg must be a positive number, got 0.0"),
    ({"min_texture": 1.0}, "min_texture must lie in [0, 1), got 1.0"),
    ({"min_texture": -0.1}, "min_texture must lie in [0, 1), got -0.1"),
    ({"depth_min_m": 3.0}, "depth_min_m must lie in [0, depth_max_m), got 3.0"),
    ({"depth_min_m": -0.1}, "depth_min_m must lie in [0, depth_max_m), got -0.1"),
])
def test_odometry_config_names_each_wrong_value_in_full(kw, msg):
    with pytest.raises(InvalidDataError) as err:
        OdometryConfig(**kw)
    assert str(err.value) == msg


def test_odometry_config_defaults_and_edges():
    c = OdometryConfig()
    assert (c.depth_scale, c.depth_min_m, c.depth_max_m, c.depth_diff_max_m, c.iterations, c.max_speed_m_s,
            c.max_turn_rad_s, c.min_information, c.texture_gradient, c.min_texture, c.cov_scale, c.keyframe_m,
            c.keyframe_deg) == (1000.0, 0.2, 3.0, 0.03, (20, 10, 5), 2.0, 3.0, 0.01, 6.0, 0.2, 0.012, 0.1, 5.0)
    OdometryConfig(keyframe_m=0.0, min_texture=0.0, depth_min_m=0.0)


def test_texture_share_by_hand():
    """A 6 x 8 picture halved to 3 x 4; gradients by forward differences on the 2 x 3 inner grid."""
    g = np.zeros((6, 8))
    g[:, 4:] = 20.0  # a vertical edge: halved, columns 2 and 3 are 20; the x difference is 20 at column 1 only
    depth = np.ones((6, 8))
    assert texture_share(g, depth) == pytest.approx(2 / 6, rel=1e-12)
    assert texture_share(g, depth, gradient=25.0) == 0.0
    assert texture_share(g, depth, gradient=19.9) == pytest.approx(2 / 6, rel=1e-12)
    rgb = np.repeat(g[..., None], 3, axis=2)
    rgb[..., 0] += 30  # the channels' mean: the same edge, 10 brighter
    assert texture_share(rgb, depth) == pytest.approx(2 / 6, rel=1e-12)
    # only pixels with depth count: the halved grid's pixel (r, c) takes depth[2r, 2c]
    d = depth.copy()
    d[0, 2] = 0  # the textured pixel (0, 1) loses its depth
    assert texture_share(g, d) == pytest.approx(1 / 5, rel=1e-12)
    assert texture_share(g, np.zeros((6, 8))) == 0.0
    # odd sizes: the last row and column are dropped before halving
    g7 = np.zeros((7, 9))
    g7[:, 4:8] = 20.0
    g7[:, 8] = 500.0
    assert texture_share(g7, np.ones((7, 9))) == pytest.approx(2 / 6, rel=1e-12)
    # a diagonal step: both differences count through their hypotenuse
    h = np.zeros((6, 8))
    h[2:, :] = 3.0
    h[:, 2:] += 3.0
    # halved: H[r, c] = 3 (r >= 1) + 3 (c >= 1): at (0, 0) dy 3 and dx 3 (hypot 4.24), at (0, 1), (0, 2) and (1, 0)
    # one of them, 3; elsewhere 0
    assert texture_share(h, depth, gradient=4.0) == pytest.approx(1 / 6, rel=1e-12)
    assert texture_share(h, depth, gradient=2.9) == pytest.approx(4 / 6, rel=1e-12)
    assert texture_share(h, depth) == 0.0


def test_without_open3d_one_line_says_how_to_get_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)
    with pytest.raises(GPR3DError) as err:
        vo.require_open3d()
    assert str(err.value) == "RGB-D odometry needs Open3D: pip install 'gpr3d[rgbd]'"

    class NoLibusb:
        def find_spec(self, name, path=None, target=None):
            if name == "open3d":
                raise ImportError("libusb-1.0.so.0: cannot open shared object file: No such file or directory")

    monkeypatch.delitem(sys.modules, "open3d")
    monkeypatch.setattr(sys, "meta_path", [NoLibusb()] + sys.meta_path)
    with pytest.raises(GPR3DError) as err:
        vo.require_open3d()
    assert str(err.value) == ("RGB-D odometry needs Open3D: pip install 'gpr3d[rgbd]' (it needs the system library "
                              "libusb-1.0: apt-get install libusb-1.0-0)")


# ------------------------------------------------------------------------------------------------ loop closures

def fused(n=30):
    """A stand-in fused result: frames every 1 s along +x at 0.1 m/s, heading 0."""
    t = np.arange(n, dtype=float)
    return SimpleNamespace(frame_t_s=t, frame_p=np.c_[0.1 * t, np.zeros(n), np.zeros(n)],
                           frame_R=np.tile(np.eye(3), (n, 1, 1)))


def test_loop_closures_from_registrations_started_at_the_fused_guess(fake):
    """Camera j in camera i registered from the fused guess; corrections past 0.5 m, failures and plain frames
    dropped; the closure's sigmas from the covariance (translation: the largest; heading: about z)."""
    res = fused()
    Tbc = np.eye(4)
    Tbc[:3, 3] = [0.2, 0.0, 0.3]

    def answer(i, j, init):
        if j == 21:
            return False, np.eye(4), np.zeros((6, 6))
        if j == 22:
            return True, np.linalg.inv(moved(0.1 * (j - i) + 0.6)), np.eye(6) * 1e4
        return True, np.linalg.inv(moved(0.1 * (j - i) - 0.01)), np.diag([1e4, 1e4, 4e4, 1e4, 2.5e3, 1e4])

    o3d = fake(answer)
    got_frames = []

    def get_frame(k):
        got_frames.append(k)
        colour = np.random.default_rng(k).integers(0, 255, (6, 8, 3)).astype(np.uint8)
        if k == 23:
            colour[:] = 90
        depth = np.full((6, 8), 1500, np.uint16)
        depth.flat[0] = 1000 + k
        return colour, depth

    cands = [(0, 20), (1, 21), (2, 22), (3, 23), (0, 24)]
    out, report = rgbd_loop_closures(get_frame, res, INTR, Tbc, OdometryConfig(), candidates=cands)
    assert report == {"candidates": 5, "closures": 2}
    assert sorted(set(got_frames)) == [0, 1, 2, 3, 20, 21, 22, 23, 24] and got_frames.count(0) == 1  # cached
    assert [(c["i"], c["j"]) for c in o3d.calls] == [(0, 20), (1, 21), (2, 22), (0, 24)]  # 23: too plain
    for c in o3d.calls:
        np.testing.assert_allclose(np.linalg.inv(c["init"]), moved(0.1 * (c["j"] - c["i"])), atol=1e-12)
    assert [(lc.i, lc.j) for lc in out] == [(0, 20), (0, 24)]
    np.testing.assert_allclose(out[0].p, [1.99, 0, 0], atol=1e-12)  # the camera rides with the IMU: the same motion
    np.testing.assert_allclose(out[0].R, np.eye(3), atol=1e-12)
    # the translation's covariance in the IMU frame takes the rotation's through the lever arm (0.2, 0, 0.3):
    # its y variance, the largest, gains 0.3^2 var(rot x) + 0.2^2 var(rot z)
    assert out[0].sigma_m == pytest.approx(math.sqrt(0.012 / 2.5e3 + 0.09 * 0.012 / 1e4 + 0.04 * 0.012 / 4e4),
                                           rel=1e-9)
    assert out[0].sigma_rad == pytest.approx(math.sqrt(0.012 / 4e4), rel=1e-9)
    # without candidates given: the revisits of the fused poses (none on a straight line)
    assert rgbd_loop_closures(get_frame, res, INTR, Tbc)[1] == {"candidates": 0, "closures": 0}
    assert vo.loop_candidates(res) == []


def test_loop_candidates_pass_their_settings_on(monkeypatch):
    import gpr3d.pose.graph as graph

    seen = []
    monkeypatch.setattr(graph, "revisits", lambda *a, **kw: seen.append((a, kw)) or [(1, 2)])
    res = fused(5)
    assert vo.loop_candidates(res, every_s=2.0, radius_m=0.3, max_angle_deg=20.0, min_gap_s=9.0) == [(1, 2)]
    (args, kw), = seen
    assert args[0] is res.frame_t_s and args[1] is res.frame_p and args[2] is res.frame_R
    assert kw == {"every_s": 2.0, "radius_m": 0.3, "max_angle_deg": 20.0, "min_gap_s": 9.0}


@pytest.mark.parametrize("answer, reason", [
    (lambda i, j, init: (False, np.eye(4), np.zeros((6, 6))), "open3d failed"),
    (lambda i, j, init: (True, np.linalg.inv(moved(1.0)), np.eye(6) * 1e4), "implausible motion"),
    (lambda i, j, init: creep(i, j, init, np.diag([0.1, 1e4, 1e4, 1e4, 1e4, 1e4])), "degenerate information"),
])
def test_every_lost_frame_is_counted(fake, answer, reason):
    fake(answer)
    rel, report = rgbd_odometry(frames(5), INTR, OdometryConfig())
    assert report["lost"] == {reason: 4} and report["registered"] == 0 and report["keyframes"] == 5
    assert not rel.valid.any()


def test_seconds_per_registration(fake, monkeypatch):
    import time

    fake()
    clock = iter(np.arange(0.0, 1000.0, 0.25))
    monkeypatch.setattr(time, "perf_counter", lambda: float(next(clock)))
    _, report = rgbd_odometry(frames(6), INTR, OdometryConfig())
    assert report["s_per_frame"] == 0.25  # each registration timed on its own: 5 of them, 0.25 s each
    fake(lambda i, j, init: (False, np.eye(4), np.zeros((6, 6))))
    _, report = rgbd_odometry(frames(2), INTR, OdometryConfig())
    assert report["s_per_frame"] == 0.25


def test_the_configured_texture_gradient_and_keyframe_distance_are_used(fake):
    fake()
    _, report = rgbd_odometry(frames(4), INTR, OdometryConfig(texture_gradient=300.0))
    assert report["lost"] == {"too little texture": 3}
    rel, _ = rgbd_odometry(frames(8), INTR, OdometryConfig(keyframe_m=1.0))
    np.testing.assert_array_equal(rel.ref, [-1, 0, 0, 0, 0, 0, 0, 0])  # 21 cm in all: one keyframe


def test_texture_share_edges_by_hand():
    g = np.zeros((6, 8))
    g[:, 4:] = 20.0
    depth = np.ones((6, 8))
    assert texture_share(g, depth, gradient=20.0) == 0.0  # exactly the gradient: not over it
    g65 = np.zeros((6, 8))
    g65[:, 4:] = 6.5
    assert texture_share(g65, depth) == pytest.approx(2 / 6, rel=1e-12)  # the default: over 6 grey levels
    # a fourth channel (alpha) is not picture
    rgba = np.zeros((6, 8, 4))
    rgba[..., 3] = np.random.default_rng(1).integers(0, 255, (6, 8))
    assert texture_share(rgba, depth) == 0.0
    # differences that vary along the other axis: a step down only in the left half, one across only in the top
    h = np.zeros((6, 8))
    h[2:, :4] = 30.0  # halved: rows 1, 2 of columns 0, 1: dy 30 at (0, 0), (0, 1); dx 30 at (1, 1)
    assert texture_share(h, depth) == pytest.approx(3 / 6, rel=1e-12)
    v = np.zeros((6, 8))
    v[:2, 2:] = 30.0  # halved: row 0 of columns 1..3: dx 30 at (0, 0); dy 30 at (0, 1), (0, 2)
    assert texture_share(v, depth) == pytest.approx(3 / 6, rel=1e-12)


def test_loop_closures_use_their_settings(fake, monkeypatch):
    seen = []
    monkeypatch.setattr(vo, "loop_candidates", lambda res, **kw: seen.append(kw) or [])
    fake()
    rgbd_loop_closures(None, fused(), INTR, np.eye(4))
    rgbd_loop_closures(None, fused(), INTR, np.eye(4), every_s=2.0, radius_m=0.3, max_angle_deg=30.0, min_gap_s=9.0)
    assert seen == [{"every_s": 1.0, "radius_m": 0.4, "max_angle_deg": 45.0, "min_gap_s": 15.0},
                    {"every_s": 2.0, "radius_m": 0.3, "max_angle_deg": 30.0, "min_gap_s": 9.0}]


def test_loop_candidates_defaults(monkeypatch):
    import gpr3d.pose.graph as graph

    seen = []
    monkeypatch.setattr(graph, "revisits", lambda *a, **kw: seen.append(kw) or [])
    vo.loop_candidates(fused(5))
    assert seen == [{"every_s": 1.0, "radius_m": 0.4, "max_angle_deg": 45.0, "min_gap_s": 15.0}]


def test_loop_closure_registrations_by_hand(fake):
    """Open3D's pinhole, options and Jacobian reach each registration; an answer with infinite numbers is dropped;
    a frame that does not fit the camera is named; the texture gradient is the configured one; the translation
    sigma is the largest of the three axes'."""
    res = fused()

    def get_frame(k):
        colour = np.random.default_rng(k).integers(0, 255, (6, 8, 3)).astype(np.uint8)
        depth = np.full((6, 8), 1500, np.uint16)
        depth.flat[0] = 1000 + k
        return (colour[:5] if k == 26 else colour), depth

    bad = np.eye(4)
    bad[1, 3] = np.inf

    def answer(i, j, init):
        if j == 21:
            return True, bad, np.eye(6) * 1e4
        return True, np.linalg.inv(moved(0.1 * (j - i))), np.diag([1e4, 1e4, 1e4, 2e3, 1e4, 1e4])

    o3d = fake(answer)
    cfg = OdometryConfig(depth_min_m=0.3, iterations=(4, 2))
    out, report = rgbd_loop_closures(get_frame, res, INTR, np.eye(4), cfg, candidates=[(0, 20), (1, 21)])
    assert report == {"candidates": 2, "closures": 1} and [(c.i, c.j) for c in out] == [(0, 20)]
    for c in o3d.calls:
        assert c["pin"] == ("pinhole", 8, 6, 5.0, 5.5, 3.5, 2.5) and c["jac"] == "hybrid"
        assert c["opt"].iteration_number_per_pyramid_level == ("IntVector", (4, 2)) and c["opt"].depth_min == 0.3
    assert out[0].sigma_m == pytest.approx(math.sqrt(0.012 / 2e3), rel=1e-9)  # x's, the largest
    with pytest.raises(InvalidDataError) as err:
        rgbd_loop_closures(get_frame, res, INTR, np.eye(4), cfg, candidates=[(0, 26)])
    assert str(err.value) == "frame 26: colour (5, 8, 3) / depth (6, 8) do not match the 8 x 6 camera"
    fake(answer)
    out, _ = rgbd_loop_closures(get_frame, res, INTR, np.eye(4), OdometryConfig(texture_gradient=300.0),
                                candidates=[(0, 20)])
    assert out == []
