"""The RGB-D renderer against geometry worked out by hand (depth along the optical axis, boxes, texture fixed
to the world)."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.render import CameraIntrinsics, FloorScene, render_rgbd
from gpr3d.pose.vo import texture_share

INTR = CameraIntrinsics(width=120, height=90, fx=100.0, fy=100.0, cx=59.5, cy=44.5)


def _down(x, y, z):
    """A camera at (x, y, z) looking straight down (optical axis -z), image x along world x."""
    T = np.eye(4)
    T[:3, :3] = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
    T[:3, 3] = (x, y, z)
    return T


def test_depth_is_along_the_optical_axis_and_boxes_stand_on_the_floor():
    scene = FloorScene(floor_z_m=-0.3, boxes=[(1.0, 1.0, 0.4, 0.4, 0.12)], texture=False)
    _, d = render_rgbd(scene, INTR, _down(0.0, 0.0, 0.5), depth_noise=0, colour_noise=0)
    assert np.all(d == 800)  # a plane parallel to the image: the same depth at every pixel, not the range
    _, d = render_rgbd(scene, INTR, _down(1.0, 1.0, 0.5), depth_noise=0, colour_noise=0)
    assert d[45, 60] == 680  # the box's top, 12 cm above the floor
    assert d[0, 0] == 800  # the floor beside it (the corner pixel looks 0.36 m, 0.36 m off: past the box)
    # a camera looking forward and 40 deg down, 0.65 m above the floor: the centre ray meets it at h / sin(40 deg)
    tilt = np.radians(40.0)
    T = np.eye(4)
    # columns: the camera's x (right), y (down) and z (optical axis) in the world
    T[:3, :3] = np.column_stack([[0.0, -1.0, 0.0], [-np.sin(tilt), 0.0, -np.cos(tilt)],
                                 [np.cos(tilt), 0.0, -np.sin(tilt)]])
    T[:3, 3] = (0.0, 0.0, 0.35)
    _, d = render_rgbd(FloorScene(texture=False), INTR, T, depth_noise=0, colour_noise=0)
    assert abs(d[44:46, 59:61].mean() - 650 / np.sin(tilt)) < 3.0


def test_texture_is_fixed_to_the_world():
    """Moving the camera by 8 pixels' worth of floor shifts the image by 8 pixels (and not otherwise)."""
    scene = FloorScene(seed=3)
    h = 0.8
    dx = 8 * h / INTR.fx
    c1, _ = render_rgbd(scene, INTR, _down(0.3, 0.2, 0.5), depth_noise=0, colour_noise=0)
    c2, _ = render_rgbd(scene, INTR, _down(0.3 + dx, 0.2, 0.5), depth_noise=0, colour_noise=0)
    a, b = c1[..., 0].astype(float), c2[..., 0].astype(float)
    assert np.abs(a[:, 8:] - b[:, :-8]).mean() < 1.0
    assert np.abs(a - b).mean() > 5.0 * np.abs(a[:, 8:] - b[:, :-8]).mean()


def test_depth_noise_grows_with_depth_squared():
    scene = FloorScene(texture=False)
    _, d = render_rgbd(scene, CameraIntrinsics(200, 200, 100.0, 100.0, 99.5, 99.5), _down(0, 0, 1.7), depth_noise=0.0025,
                       colour_noise=0, rng=np.random.default_rng(1))
    assert abs(d.astype(float).mean() - 2000.0) < 1.0
    assert d.astype(float).std() == pytest.approx(1000 * 0.0025 * 2.0**2, rel=0.05)  # 10 mm at 2 m


def test_texture_share_tells_a_textured_floor_from_a_plain_one():
    rng = np.random.default_rng(0)
    plain, _ = render_rgbd(FloorScene(texture=False), INTR, _down(0, 0, 0.5), rng=rng)
    textured, d = render_rgbd(FloorScene(seed=1), INTR, _down(0, 0, 0.5), rng=rng)
    assert texture_share(plain, d) < 0.01 and texture_share(textured, d) > 0.5
    assert texture_share(textured, np.zeros_like(d)) == 0.0  # no depth: nothing to register


def test_bad_camera_or_pose_gives_one_line():
    with pytest.raises(InvalidDataError, match="focal"):
        CameraIntrinsics(64, 48, 0.0, 50.0, 32, 24)
    with pytest.raises(InvalidDataError, match="4 x 4"):
        render_rgbd(FloorScene(), INTR, np.eye(3))
    with pytest.raises(InvalidDataError, match="box"):
        FloorScene(boxes=[(0, 0, 0.1, -0.1, 0.2)])
    d435 = CameraIntrinsics.d435i(320)
    assert (d435.width, d435.height) == (320, 240) and d435.fx == pytest.approx(191.0)


def test_plain_patch_is_plain_and_the_rest_textured():
    scene = FloorScene(seed=2, plain=[((-1.0, 1.0), (-1.0, 1.0))])
    x = np.array([0.0, 0.5, 2.0, 3.0])
    y = np.array([0.0, -0.5, 2.0, 3.0])
    c = scene.colour_at(x, y, np.full(4, scene.floor_z_m))
    assert np.all(c[:2] == 0.5) and np.all(c[2:] != 0.5)
    rng = np.random.default_rng(0)
    inside, d = render_rgbd(scene, INTR, _down(0.0, 0.0, 0.0), rng=rng)  # 0.3 m above the patch's middle
    outside, _ = render_rgbd(scene, INTR, _down(2.5, 2.5, 0.0), rng=rng)
    assert texture_share(inside, d) < 0.01 < 0.5 < texture_share(outside, d)
