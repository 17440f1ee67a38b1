"""Quaternions and headings for antenna poses (``world_from_antenna``).

Quaternions are ``(w, x, y, z)`` (``orientations_quat_wxyz``), unit norm, Hamilton
convention; the antenna's x axis is its heading (direction of travel).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "quat_from_yaw",
    "yaw_from_quat",
    "rotate_vectors",
    "normalize_quat",
    "slerp",
]


def normalize_quat(q_wxyz: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)``; raises ValueError on zero or non-finite input."""
    q = np.asarray(q_wxyz, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(q)) or np.any(n < 1e-12):
        raise ValueError("quaternions must be finite and non-zero")
    return q / n


def quat_from_yaw(yaw_rad) -> np.ndarray:
    """Quaternions ``(n, 4)`` wxyz of rotations by ``yaw_rad`` about the world z axis."""
    yaw = np.atleast_1d(np.asarray(yaw_rad, dtype=float))
    q = np.zeros(yaw.shape + (4,))
    q[..., 0] = np.cos(yaw / 2)
    q[..., 3] = np.sin(yaw / 2)
    return q


def rotate_vectors(q_wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q (..., 4)`` (broadcasting)."""
    q = np.asarray(q_wxyz, dtype=float)
    v = np.asarray(v, dtype=float)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def yaw_from_quat(q_wxyz: np.ndarray) -> np.ndarray:
    """Heading (rad, about world z, from world x) of the rotated antenna x axis."""
    x_axis = rotate_vectors(q_wxyz, np.array([1.0, 0.0, 0.0]))
    return np.arctan2(x_axis[..., 1], x_axis[..., 0])


def slerp(q0: np.ndarray, q1: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions, element-wise.

    ``q0``, ``q1``: ``(n, 4)``; ``frac``: ``(n,)`` in [0, 1].
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = np.array(q1, dtype=float)
    frac = np.asarray(frac, dtype=float)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)  # shortest arc
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-9
    safe = np.where(small, 1.0, sin_t)
    a = np.where(small, 1.0 - frac, np.sin((1.0 - frac) * theta) / safe)
    b = np.where(small, frac, np.sin(frac * theta) / safe)
    return normalize_quat(a * q0 + b * q1)
