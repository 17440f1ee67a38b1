"""The RGB-D renderer by hand: rays, depths, boxes, texture lookups and noise worked out pixel by pixel here."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from gpr3d.core.camera import CameraIntrinsics
from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.render import FloorScene, _texture, render_rgbd, rig_camera_poses

INTR = CameraIntrinsics(width=9, height=7, fx=6.0, fy=5.0, cx=4.0, cy=3.0)


def _down(x=0.0, y=0.0, z=1.0):
    """A camera at (x, y, z) looking straight down: camera x along world x, camera y along world -y."""
    T = np.eye(4)
    T[:3, :3] = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    T[:3, 3] = [x, y, z]
    return T


def _tex_lookup(scene, x, y, z):
    """Bilinear lookup of the scene's texture, written out (the sides of boxes shifted as documented)."""
    t = scene._tex
    n = t.shape[0]
    u = (x + 0.7 * (z - scene.floor_z_m)) / scene.texture_m * n
    v = (y - 1.3 * (z - scene.floor_z_m)) / scene.texture_m * n
    i, j = math.floor(u), math.floor(v)
    fu, fv = u - i, v - j
    a = t[i % n, j % n] * (1 - fv) + t[i % n, (j + 1) % n] * fv
    b = t[(i + 1) % n, j % n] * (1 - fv) + t[(i + 1) % n, (j + 1) % n] * fv
    return a * (1 - fu) + b * fu


def test_a_floor_seen_from_above_pixel_by_pixel():
    scene = FloorScene(floor_z_m=-0.3, seed=3, texture_m=2.0)
    colour, depth = render_rgbd(scene, INTR, _down(0.2, -0.1, 1.0), depth_noise=0.0, colour_noise=0.0)
    assert colour.shape == (7, 9, 3) and colour.dtype == np.uint8 and depth.dtype == np.uint16
    assert (depth == 1300).all()  # straight down, 1.3 m: the depth is along the optical axis for every pixel
    for v in range(7):
        for u in range(9):
            x, y = 0.2 + 1.3 * (u - 4) / 6.0, -0.1 - 1.3 * (v - 3) / 5.0
            grey = _tex_lookup(scene, x, y, -0.3) * 200 + 30
            assert colour[v, u].tolist() == [int(np.clip(np.round(grey), 0, 255))] * 3, (u, v)


def test_a_box_stands_on_the_floor_and_its_top_is_nearer():
    scene = FloorScene(floor_z_m=-0.3, boxes=[(0.0, 0.0, 0.4, 0.4, 0.2)], texture=False)
    colour, depth = render_rgbd(scene, INTR, _down(0.0, 0.0, 1.0), depth_noise=0.0, colour_noise=0.0)
    # the top at -0.1 (1.1 m away) covers |x|, |y| <= 0.2 m: |u - 4| <= 0.2 x 6 / 1.1, |v - 3| <= 0.2 x 5 / 1.1
    for v in range(7):
        for u in range(9):
            on_top = abs(u - 4) <= 0.2 * 6 / 1.1 and abs(v - 3) <= 0.2 * 5 / 1.1
            on_side = not on_top and abs(u - 4) * 1.3 / 6 <= 0.2 and abs(v - 3) * 1.3 / 5 <= 0.2
            if on_top:
                assert depth[v, u] == 1100, (u, v)
            elif not on_side:
                assert depth[v, u] == 1300, (u, v)
    assert (colour == 130).all()  # no texture: a plain 0.5 grey
    # a box behind the camera or out of range is not seen; a box under the floor's level is not either
    far = FloorScene(floor_z_m=-0.3, boxes=[(9.0, 0.0, 0.4, 0.4, 0.2)], texture=False)
    assert (render_rgbd(far, INTR, _down(), depth_noise=0, colour_noise=0)[1] == 1300).all()


def test_nothing_beyond_the_range_and_nothing_above_the_horizon():
    scene = FloorScene(floor_z_m=-0.3, texture=False)
    colour, depth = render_rgbd(scene, INTR, _down(0.0, 0.0, 3.5), depth_noise=0, colour_noise=0)
    assert (depth == 0).all() and (colour == 30).all()  # 3.8 m: past 3 m, no return, the background grey
    _, depth = render_rgbd(scene, INTR, _down(0.0, 0.0, 3.5), depth_noise=0, colour_noise=0, max_depth_m=3.8)
    assert (depth == 3800).all()  # exactly at the range: seen
    up = _down()
    up[:3, :3] = np.diag([1.0, 1.0, 1.0])  # looking up (z forward = world +z): the floor is behind
    colour, depth = render_rgbd(scene, INTR, up, depth_noise=0, colour_noise=0)
    assert (depth == 0).all() and (colour == 30).all()


def test_noise_draws_from_the_generator_in_order():
    scene = FloorScene(floor_z_m=-0.3, texture=False)
    colour, depth = render_rgbd(scene, INTR, _down(), depth_noise=0.01, colour_noise=3.0,
                                rng=np.random.default_rng(5))
    rng = np.random.default_rng(5)
    grey = 130 + rng.normal(0, 3.0, (7, 9))
    z = 1.3 + rng.normal(0, 1.0, (7, 9)) * 0.01 * 1.3**2
    assert (colour[..., 0] == np.clip(np.round(grey), 0, 255).astype(np.uint8)).all()
    assert (depth == np.round(z * 1000).astype(np.uint16)).all()
    c0, d0 = render_rgbd(scene, INTR, _down())  # the default generator is seeded: the same frame twice
    c1, d1 = render_rgbd(scene, INTR, _down())
    assert (c0 == c1).all() and (d0 == d1).all() and not (d0 == 1300).all()


def test_plain_patches_and_the_texture_s_range():
    scene = FloorScene(seed=1, plain=[((-1.0, 0.0), (-1.0, 1.0))])
    x, y = np.array([-0.5, 0.0, 0.5]), np.array([0.2, 1.0, 0.2])
    got = scene.colour_at(x, y, np.full(3, scene.floor_z_m))
    assert got[0] == 0.5 and got[1] == 0.5  # inside and on the patch's edge
    assert got[2] == pytest.approx(_tex_lookup(scene, 0.5, 0.2, scene.floor_z_m), rel=1e-12)
    t = scene._tex
    assert t.shape == (1024, 1024) and t.min() == 0.0 and t.max() == 1.0
    np.testing.assert_array_equal(t, _texture(np.random.default_rng(1)))
    assert not np.array_equal(t, FloorScene(seed=2)._tex)
    assert FloorScene(texture=False)._tex is None
    assert FloorScene(texture=False).colour_at(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3))).shape == (2, 3)


def test_the_texture_by_its_recipe():
    rng = np.random.default_rng(4)
    got = _texture(np.random.default_rng(4), n=32)
    out = np.zeros((32, 32))
    k = np.fft.fftfreq(32) * 32
    kk = np.hypot(*np.meshgrid(k, k, indexing="ij"))
    for octave, weight in ((4, 1.0), (16, 0.7), (64, 0.5), (256, 0.35)):
        layer = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(32, 32))) * np.exp(-(kk / octave) ** 2)))
        out += weight * layer / layer.std()
    out = (out - out.min()) / (out - out.min()).max()
    np.testing.assert_allclose(got, out, rtol=0, atol=1e-12)


def test_random_scenes_by_their_draws():
    scene = FloorScene.random(area=((0.0, 1.0), (2.0, 4.0)), n_boxes=3, seed=7, texture=False)
    rng = np.random.default_rng(np.random.SeedSequence([7, 21]))
    want = [(rng.uniform(0, 1), rng.uniform(2, 4), rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4),
             rng.uniform(0.05, 0.25)) for _ in range(3)]
    assert scene.boxes == [tuple(float(v) for v in b) for b in want] and scene.seed == 7
    d = FloorScene.random(texture=False)
    assert len(d.boxes) == 40 and d.seed == 0
    assert all(-6 <= b[0] <= 6 and -6 <= b[1] <= 6 for b in d.boxes)
    rng = np.random.default_rng(np.random.SeedSequence([0, 21]))
    assert d.boxes[0][0] == float(rng.uniform(-6.0, 6.0))


@pytest.mark.parametrize("box", [(0, 0, 0.0, 0.1, 0.1), (0, 0, 0.1, 0.0, 0.1), (0, 0, 0.1, 0.1, 0.0), (0, 0, 1, 1)])
def test_boxes_need_positive_sizes(box):
    with pytest.raises(InvalidDataError) as err:
        FloorScene(boxes=[box], texture=False)
    assert str(err.value) == f"a box is (x, y, size_x, size_y, height) with positive sizes, got {box!r}"


def test_rig_camera_poses_by_hand():
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    Tbc = np.eye(4)
    Tbc[:3, :3] = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    Tbc[:3, 3] = [0.1, 0.2, 0.3]
    calls = []

    def truth(t):
        calls.append(t)
        return {"R": np.stack([np.eye(3), Rz]), "p": np.array([[1.0, 2, 3], [4, 5, 6]])}

    run = SimpleNamespace(truth=truth, config=SimpleNamespace(imu_T_camera=Tbc))
    T = rig_camera_poses(run, [0, 1])
    assert calls[0].dtype == np.float64
    np.testing.assert_allclose(T[0][:3, :3], Tbc[:3, :3])
    np.testing.assert_allclose(T[0][:3, 3], [1.1, 2.2, 3.3])
    np.testing.assert_allclose(T[1][:3, :3], Rz @ Tbc[:3, :3], atol=1e-15)
    np.testing.assert_allclose(T[1][:3, 3], [4 - 0.2, 5 + 0.1, 6.3], atol=1e-15)
    np.testing.assert_array_equal(T[:, 3], [[0, 0, 0, 1]] * 2)
