"""RGB-D frames of a synthetic site, rendered from any camera pose: what a D435i on the cart would record.

The site is a textured floor (a horizontal plane) with a few boxes standing on it (kerbs, tool cases: the
3D structure that depth odometry needs). Every pixel's ray is cast against the plane and the boxes; the
colour comes from a multi-scale random texture fixed to the world (so it moves with the scene, not the
camera), the depth is the distance along the optical axis, with a D435i-like noise that grows with the
square of the depth, quantised to millimetres as the camera writes it (``uint16``, 0 = no return).

Camera frame: x right, y down, z forward (the optical axis); pixel ``(u, v)`` looks along
``((u - cx) / fx, (v - cy) / fy, 1)``.

>>> intr = CameraIntrinsics.d435i(width=320)                             # doctest: +SKIP
>>> colour, depth = render_rgbd(FloorScene(), intr, world_T_camera)     # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpr3d.core.camera import CameraIntrinsics
from gpr3d.core.errors import InvalidDataError

__all__ = ["CameraIntrinsics", "FloorScene", "render_rgbd", "rig_camera_poses"]


def _texture(rng: np.random.Generator, n: int = 1024) -> np.ndarray:
    """A tileable multi-scale random texture in [0, 1] (sum of smoothed noise at four octaves)."""
    out = np.zeros((n, n))
    for octave, weight in ((4, 1.0), (16, 0.7), (64, 0.5), (256, 0.35)):
        f = np.fft.fft2(rng.normal(size=(n, n)))
        k = np.fft.fftfreq(n) * n
        kk = np.hypot(*np.meshgrid(k, k, indexing="ij"))
        layer = np.real(np.fft.ifft2(f * np.exp(-(kk / octave) ** 2)))
        out += weight * layer / layer.std()
    out -= out.min()
    return out / out.max()


@dataclass
class FloorScene:
    """A textured floor at height ``floor_z_m`` with boxes ``(x, y, size_x, size_y, height)`` (m) on it.

    ``texture_m`` is the size of one texture tile (it repeats beyond it); ``texture=False`` gives a
    plain grey floor and boxes (no texture for the colour term: what makes odometry fail), ``plain`` a list of
    ``((x0, x1), (y0, y1))`` patches of plain floor in a textured one (fresh asphalt, a tarpaulin)."""

    floor_z_m: float = -0.3
    boxes: list = field(default_factory=list)
    texture: bool = True
    texture_m: float = 4.0
    seed: int = 0
    plain: list = field(default_factory=list)

    def __post_init__(self):
        self._tex = _texture(np.random.default_rng(self.seed)) if self.texture else None
        for b in self.boxes:
            if len(b) != 5 or not (b[2] > 0 and b[3] > 0 and b[4] > 0):
                raise InvalidDataError(f"a box is (x, y, size_x, size_y, height) with positive sizes, got {b!r}")

    @classmethod
    def random(cls, area=((-6.0, 6.0), (-6.0, 6.0)), n_boxes: int = 40, seed: int = 0, **kw) -> "FloorScene":
        """A floor with ``n_boxes`` boxes (10-40 cm across, 5-25 cm high) scattered over ``area``."""
        rng = np.random.default_rng(np.random.SeedSequence([seed, 21]))
        (x0, x1), (y0, y1) = area
        boxes = [(float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)), float(rng.uniform(0.1, 0.4)),
                  float(rng.uniform(0.1, 0.4)), float(rng.uniform(0.05, 0.25))) for _ in range(n_boxes)]
        return cls(boxes=boxes, seed=seed, **kw)

    def colour_at(self, x, y, z) -> np.ndarray:
        """Grey level in [0, 1] of the surface point(s) ``(x, y, z)``: the texture, or 0.5 without one."""
        if self._tex is None:
            return np.full(np.shape(x), 0.5)
        n = self._tex.shape[0]
        # boxes' sides take the texture at a shifted place, so they differ from the floor beside them
        u = (np.asarray(x) + 0.7 * (np.asarray(z) - self.floor_z_m)) / self.texture_m * n
        v = (np.asarray(y) - 1.3 * (np.asarray(z) - self.floor_z_m)) / self.texture_m * n
        i0, j0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        fu, fv = u - i0, v - j0
        t = self._tex
        a = t[i0 % n, j0 % n] * (1 - fv) + t[i0 % n, (j0 + 1) % n] * fv
        b = t[(i0 + 1) % n, j0 % n] * (1 - fv) + t[(i0 + 1) % n, (j0 + 1) % n] * fv
        out = a * (1 - fu) + b * fu
        for (x0, x1), (y0, y1) in self.plain:
            out = np.where((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1), 0.5, out)
        return out


def render_rgbd(scene: FloorScene, intr: CameraIntrinsics, world_T_camera, *, depth_noise: float = 0.0025,
                colour_noise: float = 2.0, max_depth_m: float = 3.0, rng: np.random.Generator | None = None):
    """Colour (h, w, 3) ``uint8`` and depth (h, w) ``uint16`` millimetres seen from ``world_T_camera`` (4 x 4).

    ``depth_noise``: the depth's standard deviation is ``depth_noise * z**2`` (m; 0.0025 gives 1.6 mm at 0.8 m,
    1 cm at 2 m, as a D435i); ``colour_noise`` in grey levels; no return beyond ``max_depth_m`` (depth 0)."""
    T = np.asarray(world_T_camera, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidDataError(f"world_T_camera must be a finite 4 x 4 pose, got shape {T.shape}")
    R, o = T[:3, :3], T[:3, 3]
    v, u = np.mgrid[0 : intr.height, 0 : intr.width].astype(float)
    d = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1) @ R.T  # z_cam = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (scene.floor_z_m - o[2]) / d[..., 2]
    t = np.where(t > 0, t, np.inf)
    for bx, by, sx, sy, h in scene.boxes:
        if np.hypot(bx - o[0], by - o[1]) > max_depth_m + np.hypot(sx, sy):
            continue  # out of range: no pixel can see it
        lo = np.array([bx - sx / 2, by - sy / 2, scene.floor_z_m])
        hi = np.array([bx + sx / 2, by + sy / 2, scene.floor_z_m + h])
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (lo - o) / d, (hi - o) / d
        near = np.nanmax(np.minimum(t1, t2), axis=-1)
        far = np.nanmin(np.maximum(t1, t2), axis=-1)
        hit = (near <= far) & (near > 0)
        t = np.where(hit & (near < t), near, t)
    seen = np.isfinite(t) & (t <= max_depth_m)
    p = o + d * np.where(seen, t, 0.0)[..., None]
    grey = np.where(seen, scene.colour_at(p[..., 0], p[..., 1], p[..., 2]), 0.0) * 200.0 + 30.0
    rng = rng or np.random.default_rng(0)
    if colour_noise > 0:
        grey = grey + rng.normal(0.0, colour_noise, grey.shape)
    colour = np.repeat(np.clip(np.round(grey), 0, 255).astype(np.uint8)[..., None], 3, axis=-1)
    z = np.where(seen, t, 0.0)
    if depth_noise > 0:
        z = z + np.where(seen, rng.normal(0.0, 1.0, z.shape) * depth_noise * z**2, 0.0)
    depth = np.clip(np.round(z * 1000.0), 0, 65535).astype(np.uint16)
    return colour, depth


def rig_camera_poses(run, t_imu) -> np.ndarray:
    """The rig's true camera poses (world from camera, (n, 4, 4)) at IMU times ``t_imu``."""
    g = run.truth(np.asarray(t_imu, dtype=float))
    Tbc = run.config.imu_T_camera
    n = g["R"].shape[0]
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = g["R"] @ Tbc[:3, :3]
    T[:, :3, 3] = g["p"] + g["R"] @ Tbc[:3, 3]
    return T
