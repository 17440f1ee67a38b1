"""Visual odometry from RGB-D frames through Open3D's RGB-D odometry (photometric and depth terms).

Each frame is registered to a keyframe (Open3D's ``compute_rgbd_odometry`` with the hybrid Jacobian,
started from the last motion carried on: a cart's motion changes little in 1/15 s); the keyframe moves on
once the camera has moved 10 cm or turned 5 deg from it (``keyframe_m``, ``keyframe_deg``; 0 registers frame
to frame), so a cart that stands or creeps gathers no drift. A registration is not used
blindly: it is marked lost, with the reason, when Open3D reports failure, when either image has too
little texture for the photometric term (the share of pixels with depth whose intensity gradient, on the
image halved against sensor noise, exceeds ``texture_gradient`` grey levels falls under ``min_texture``: a
plain floor fixes only three of the six degrees of freedom through its depth, and Open3D's information
matrix, built from the geometry alone, does not show it), when the information matrix is degenerate, or
when the motion is implausible for a cart (faster than ``max_speed_m_s`` or turning faster than
``max_turn_rad_s``). The output is :class:`~gpr3d.pose.imu.RelativePoses`, ready for
:func:`gpr3d.pose.eskf.fuse`, with a covariance from the information matrix (``cov_scale / information``; the
scale is calibrated on rendered frames, see ``benchmarks/eval_rgbd_odometry.py``).

Open3D is an optional extra (``pip install 'gpr3d[rgbd]'``; on Debian it also needs ``libusb-1.0-0``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.pose.imu import RelativePoses, so3_log
from gpr3d.pose.render import CameraIntrinsics

__all__ = ["OdometryConfig", "rgbd_odometry", "loop_candidates", "rgbd_loop_closures", "require_open3d", "texture_share"]


def require_open3d():
    """Open3D, or a one-line error that says how to get it."""
    try:
        import open3d
    except ImportError as e:  # not installed, or its libusb missing
        hint = (" (it needs the system library libusb-1.0: apt-get install libusb-1.0-0)"
                if "libusb" in str(e) else "")
        raise GPR3DError(f"RGB-D odometry needs Open3D: pip install 'gpr3d[rgbd]'{hint}") from None
    return open3d


@dataclass
class OdometryConfig:
    """Settings of :func:`rgbd_odometry`."""

    depth_scale: float = 1000.0  #: depth units per metre (a D435i writes millimetres)
    depth_min_m: float = 0.2
    depth_max_m: float = 3.0
    depth_diff_max_m: float = 0.03  #: a point pair further apart in depth is no correspondence
    iterations: tuple = (20, 10, 5)  #: per pyramid level, coarse to fine
    max_speed_m_s: float = 2.0  #: a faster motion between frames is taken as a failed registration
    max_turn_rad_s: float = 3.0
    #: the information's smallest eigenvalue below this (per pixel of the image) marks a degenerate scene
    min_information: float = 0.01
    texture_gradient: float = 6.0  #: grey levels (on the image halved): a textured pixel's gradient
    min_texture: float = 0.2  #: share of textured pixels (with depth) under which a frame is too plain
    #: covariance = cov_scale * inverse(information): calibrated on rendered frames (D435i noise, 320 x 240),
    #: where it makes the relative motions' NEES average 6 (1800 frames, benchmarks/results/rgbd_odometry.md)
    cov_scale: float = 0.012
    #: register each frame to a keyframe, which moves on to the newest frame once the camera lies ``keyframe_m``
    #: or ``keyframe_deg`` from it (a still or slow cart then gathers no drift); 0: frame to frame
    keyframe_m: float = 0.1
    keyframe_deg: float = 5.0

    def __post_init__(self):
        if not (np.isfinite(self.keyframe_m) and self.keyframe_m >= 0):
            raise InvalidDataError(f"keyframe_m must be 0 (frame to frame) or positive, got {self.keyframe_m!r}")
        for name in ("depth_scale", "depth_max_m", "depth_diff_max_m", "max_speed_m_s", "max_turn_rad_s",
                     "min_information", "texture_gradient", "cov_scale", "keyframe_deg"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InvalidDataError(f"{name} must be a positive number, got {v!r}")
        if not 0 <= self.min_texture < 1:
            raise InvalidDataError(f"min_texture must lie in [0, 1), got {self.min_texture!r}")
        if not 0 <= self.depth_min_m < self.depth_max_m:
            raise InvalidDataError(f"depth_min_m must lie in [0, depth_max_m), got {self.depth_min_m!r}")


def texture_share(colour, depth, gradient: float = 6.0) -> float:
    """Share of the pixels with depth whose intensity gradient exceeds ``gradient`` grey levels, measured on the
    image halved (2 x 2 means) so that sensor noise of a few levels does not count as texture."""
    g = np.asarray(colour, dtype=float)
    g = g[..., :3].mean(-1) if g.ndim == 3 else g
    h, w = g.shape[0] // 2 * 2, g.shape[1] // 2 * 2
    g = g[:h, :w].reshape(h // 2, 2, w // 2, 2).mean((1, 3))
    m = np.hypot(np.diff(g, axis=0)[:, :-1], np.diff(g, axis=1)[:-1, :])
    ok = np.asarray(depth)[:h:2, :w:2][:-1, :-1] > 0
    return float(np.mean(m[ok] > gradient)) if ok.any() else 0.0


def _open3d_odometry(o3d, cfg: OdometryConfig, intr: CameraIntrinsics):
    """Open3D's pinhole, odometry options and the hybrid (photometric + depth) Jacobian for ``cfg``."""
    pin = o3d.camera.PinholeCameraIntrinsic(intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy)
    opt = o3d.pipelines.odometry.OdometryOption()
    opt.iteration_number_per_pyramid_level = o3d.utility.IntVector(list(cfg.iterations))
    opt.depth_diff_max, opt.depth_min, opt.depth_max = cfg.depth_diff_max_m, cfg.depth_min_m, cfg.depth_max_m
    return pin, opt, o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm()


def _rgbd(o3d, colour, depth, cfg: OdometryConfig, intr: CameraIntrinsics, k: int):
    colour, depth = np.asarray(colour), np.asarray(depth)
    if colour.shape[:2] != (intr.height, intr.width) or depth.shape != (intr.height, intr.width):
        raise InvalidDataError(f"frame {k}: colour {colour.shape} / depth {depth.shape} do not match the "
                               f"{intr.width} x {intr.height} camera")
    if colour.ndim == 3 and colour.shape[2] == 3:
        colour = np.ascontiguousarray(colour.astype(np.uint8))
    elif colour.ndim == 2:
        colour = np.ascontiguousarray(np.repeat(colour.astype(np.uint8)[..., None], 3, axis=-1))
    else:
        raise InvalidDataError(f"frame {k}: colour must be h x w x 3 or h x w, got {colour.shape}")
    if depth.dtype.kind == "f" and not np.all(np.isfinite(depth)):
        depth = np.where(np.isfinite(depth), depth, 0)
    depth = np.ascontiguousarray(depth.astype(np.float32 if depth.dtype.kind == "f" else np.uint16))
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(colour), o3d.geometry.Image(depth), depth_scale=cfg.depth_scale,
        depth_trunc=cfg.depth_max_m, convert_rgb_to_intensity=True)


def rgbd_odometry(frames: Iterable, intr: CameraIntrinsics, cfg: OdometryConfig | None = None, *,
                  progress=None) -> tuple[RelativePoses, dict]:
    """Odometry of ``frames``: an iterable of ``(t_s, colour, depth)`` (camera clock).

    Each frame is registered to the live keyframe (``cfg.keyframe_m``; with 0, to the frame before), started
    from the last motion carried one frame on. Returns the relative camera motions (frame ``k`` in its
    keyframe ``ref[k]``; frame 0 and every lost frame are marked invalid, and a lost frame becomes the next
    keyframe) and a report: frames, keyframes, lost frames by reason, seconds per registration."""
    import time

    o3d = require_open3d()
    cfg = cfg or OdometryConfig()
    pin, opt, jac = _open3d_odometry(o3d, cfg, intr)
    ts, Rs, ps, covs, valid, refs = [], [], [], [], [], []
    reasons = {"open3d failed": 0, "too little texture": 0, "degenerate information": 0, "implausible motion": 0}
    key = None  # (image, texture share, frame index, camera time) of the keyframe
    prev_t = None
    # the camera's last motion from the keyframe, and its motion over the last frame interval (for the guess)
    from_key, step = np.eye(4), np.eye(4)
    n_pix = intr.width * intr.height
    wall, registrations, keyframes = 0.0, 0, 0
    for k, (t, colour, depth) in enumerate(frames):
        t = float(t)
        if not np.isfinite(t) or (prev_t is not None and t <= prev_t):
            raise InvalidDataError(f"frame {k}: its time {t!r} does not increase")
        img = _rgbd(o3d, colour, depth, cfg, intr, k)
        tex = texture_share(colour, depth, cfg.texture_gradient)
        R, p, cov, ok = np.eye(3), np.zeros(3), np.eye(6), False
        if key is not None:
            kimg, ktex, kidx, kt = key
            guess_motion = from_key @ step
            t0 = time.perf_counter()
            # the transform maps points of the keyframe into this frame: the camera's motion is its inverse
            success, trans, info = o3d.pipelines.odometry.compute_rgbd_odometry(kimg, img, pin,
                                                                                np.linalg.inv(guess_motion), jac, opt)
            wall += time.perf_counter() - t0
            registrations += 1
            motion = np.linalg.inv(trans) if success and np.all(np.isfinite(trans)) else np.eye(4)
            lam = np.linalg.eigvalsh(0.5 * (info + info.T)) if success else np.zeros(6)
            dt = t - kt
            if not success or not np.all(np.isfinite(trans)):
                reasons["open3d failed"] += 1
            elif min(tex, ktex) < cfg.min_texture:
                reasons["too little texture"] += 1
            elif lam[0] < cfg.min_information * n_pix:
                reasons["degenerate information"] += 1
            elif (np.linalg.norm(motion[:3, 3]) > cfg.max_speed_m_s * dt
                  or np.linalg.norm(so3_log(motion[:3, :3])) > cfg.max_turn_rad_s * dt):
                reasons["implausible motion"] += 1
            else:
                R, p, ok = motion[:3, :3], motion[:3, 3], True
                cov = cfg.cov_scale * np.linalg.inv(0.5 * (info + info.T))
            refs.append(kidx)
            if ok:
                step = np.linalg.inv(from_key) @ motion
                from_key = motion
            if progress is not None:
                progress(k)
        else:
            refs.append(-1)
        ts.append(t)
        Rs.append(R)
        ps.append(p)
        covs.append(cov)
        valid.append(ok)
        # a new keyframe: the first frame, a lost frame (tracking restarts from it), or a view that has moved on
        if (key is None or not ok or cfg.keyframe_m == 0 or np.linalg.norm(p) > cfg.keyframe_m
                or np.linalg.norm(so3_log(R)) > np.deg2rad(cfg.keyframe_deg)):
            key = (img, tex, k, t)
            keyframes += 1
            from_key = np.eye(4)
            if not ok:
                step = np.eye(4)
        prev_t = t
    if len(ts) < 2:
        raise InvalidDataError(f"odometry needs at least two frames, got {len(ts)}")
    vo = RelativePoses(np.array(ts), np.array(Rs), np.array(ps), np.array(covs), np.array(valid), np.array(refs))
    report = {"frames": len(ts), "keyframes": keyframes, "registered": int(np.sum(valid)),
              "lost": {k: v for k, v in reasons.items() if v}, "s_per_frame": wall / max(1, registrations)}
    return vo, report


def loop_candidates(res, *, every_s: float = 1.0, radius_m: float = 0.4, max_angle_deg: float = 45.0,
                    min_gap_s: float = 15.0) -> list[tuple[int, int]]:
    """Revisits (:func:`gpr3d.pose.graph.revisits`) among the frames of a fused trajectory, by its poses."""
    from gpr3d.pose.graph import revisits

    return revisits(res.frame_t_s, res.frame_p, res.frame_R, every_s=every_s, radius_m=radius_m,
                    max_angle_deg=max_angle_deg, min_gap_s=min_gap_s)


def rgbd_loop_closures(get_frame, res, intr: CameraIntrinsics, imu_T_camera, cfg: OdometryConfig | None = None, *,
                       every_s: float = 1.0, radius_m: float = 0.4, max_angle_deg: float = 45.0,
                       min_gap_s: float = 15.0, max_correction_m: float = 0.5,
                       candidates: list | None = None) -> tuple[list, dict]:
    """Loop closures from RGB-D frames: revisits found from the fused poses, measured by registration.

    ``get_frame(k)`` returns frame ``k``'s ``(colour, depth)`` (frame indices of ``res``, a
    :class:`~gpr3d.pose.eskf.FusionResult`). The pairs of :func:`loop_candidates` (or ``candidates``) are
    registered with Open3D, started from the fused relative pose; a registration that fails, sees too little
    texture, or moves the guess by more than ``max_correction_m`` is dropped. Returns
    :class:`~gpr3d.pose.graph.LoopClosure` s (for :func:`gpr3d.pose.graph.close_loops`) and a report."""
    from gpr3d.pose.eskf import camera_to_imu_motion
    from gpr3d.pose.graph import LoopClosure

    o3d = require_open3d()
    cfg = cfg or OdometryConfig()
    pin, opt, jac = _open3d_odometry(o3d, cfg, intr)
    Tbc = np.asarray(imu_T_camera, dtype=float)
    out, tried = [], 0
    cache = {}

    def image(k):
        if k not in cache:
            colour, depth = get_frame(k)
            cache[k] = (_rgbd(o3d, colour, depth, cfg, intr, k), texture_share(colour, depth, cfg.texture_gradient))
        return cache[k]

    def cam_pose(k):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = res.frame_R[k], res.frame_p[k]
        return T @ Tbc

    if candidates is None:
        candidates = loop_candidates(res, every_s=every_s, radius_m=radius_m, max_angle_deg=max_angle_deg,
                                     min_gap_s=min_gap_s)
    for i, j in candidates:
        tried += 1
        (img_i, tex_i), (img_j, tex_j) = image(i), image(j)
        if min(tex_i, tex_j) < cfg.min_texture:
            continue
        guess_motion = np.linalg.inv(cam_pose(i)) @ cam_pose(j)  # camera j in camera i, by the fusion
        success, trans, info = o3d.pipelines.odometry.compute_rgbd_odometry(img_i, img_j, pin,
                                                                            np.linalg.inv(guess_motion), jac, opt)
        if not success or not np.all(np.isfinite(trans)):
            continue
        motion = np.linalg.inv(trans)
        if np.linalg.norm(motion[:3, 3] - guess_motion[:3, 3]) > max_correction_m:
            continue
        cov = cfg.cov_scale * np.linalg.inv(0.5 * (info + info.T))
        R_b, p_b, cov_b = camera_to_imu_motion(motion[:3, :3], motion[:3, 3], cov, Tbc)
        out.append(LoopClosure(i, j, R_b, p_b, float(np.sqrt(max(np.max(np.diag(cov_b)[3:]), 1e-8))),
                               float(np.sqrt(max(cov_b[2, 2], 1e-10)))))
    return out, {"candidates": tried, "closures": len(out)}
