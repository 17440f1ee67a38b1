"""Antenna paths for simulated surveys: smooth random walks and straight grid lines.

Poses are ``world_from_antenna`` on the surface (z = 0): the antenna's x axis
points along the direction of travel, as on a cart.
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.trajectory import Trajectory

__all__ = ["random_walk", "grid_lines"]


def random_walk(n_traces: int, *, area=((0.0, 2.0), (0.0, 2.0)), step_m: float = 0.01, turn_rate: float = 0.15,
                speed_m_s: float = 0.5, explore: float = 1.0, seed: int = 0) -> Trajectory:
    """A smooth random walk covering ``area`` ((x0, x1), (y0, y1)) with one trace every ``step_m``.

    The heading changes by a smoothed random turn rate (rad per step, standard
    deviation ``turn_rate``); near an edge the walker turns back inside. Like an
    operator who looks where the cart has not been, the walker is also pulled toward
    less-visited ground: it keeps a count of steps per 10 cm cell and steers toward
    the side, 40 cm ahead, with fewer visits (``explore`` scales that pull; 0 gives the
    plain random walk). Timestamps follow from ``speed_m_s`` (survey-wheel triggering:
    one trace per step).
    """
    rng = np.random.default_rng(seed)
    (x0, x1), (y0, y1) = area
    pos = np.zeros((n_traces, 3))
    yaw = np.zeros(n_traces)
    p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1)])
    h = rng.uniform(-np.pi, np.pi)
    w = 0.0
    margin = 0.02 * min(x1 - x0, y1 - y0)
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    cell, look, side = 0.1, 0.4, 0.5
    visits = np.zeros((int(np.ceil((x1 - x0) / cell)) + 1, int(np.ceil((y1 - y0) / cell)) + 1))

    def cell_of(q):
        return (int(np.clip((q[0] - x0) / cell, 0, visits.shape[0] - 1)),
                int(np.clip((q[1] - y0) / cell, 0, visits.shape[1] - 1)))

    for i in range(n_traces):
        w = 0.9 * w + 0.1 * rng.normal(0, turn_rate * 3)
        if explore > 0:
            left = visits[cell_of(p + look * np.array([np.cos(h + side), np.sin(h + side)]))]
            right = visits[cell_of(p + look * np.array([np.cos(h - side), np.sin(h - side)]))]
            w += 0.1 * explore * turn_rate * np.tanh((right - left) / (1.0 + left + right) * 4)
        ahead = p + max(5 * step_m, 0.05) * np.array([np.cos(h), np.sin(h)])
        if not (x0 + margin < ahead[0] < x1 - margin and y0 + margin < ahead[1] < y1 - margin):
            to_c = np.arctan2(*(centre - p)[::-1])
            diff = (to_c - h + np.pi) % (2 * np.pi) - np.pi
            w = np.clip(diff, -0.2, 0.2)
        h = h + w
        p = p + step_m * np.array([np.cos(h), np.sin(h)])
        p = np.clip(p, [x0, y0], [x1, y1])
        visits[cell_of(p)] += 1
        pos[i, :2] = p
        yaw[i] = h
    t = np.arange(n_traces) * step_m / speed_m_s
    return Trajectory(t, pos, quat_from_yaw(yaw))


def grid_lines(*, area=((0.0, 2.0), (0.0, 2.0)), line_spacing_m: float = 0.25, step_m: float = 0.01,
               directions: str = "xy", speed_m_s: float = 0.5) -> Trajectory:
    """Straight survey lines: along x (``"x"``), along y (``"y"``) or both (``"xy"``), as a trajectory."""
    (x0, x1), (y0, y1) = area
    pos, yaw = [], []
    if "x" in directions:
        for k, y in enumerate(np.arange(y0, y1 + 1e-9, line_spacing_m)):
            xs = np.arange(x0, x1 + 1e-9, step_m)
            xs = xs if k % 2 == 0 else xs[::-1]
            pos.append(np.stack([xs, np.full_like(xs, y), np.zeros_like(xs)], axis=1))
            yaw.append(np.full(xs.size, 0.0 if k % 2 == 0 else np.pi))
    if "y" in directions:
        for k, x in enumerate(np.arange(x0, x1 + 1e-9, line_spacing_m)):
            ys = np.arange(y0, y1 + 1e-9, step_m)
            ys = ys if k % 2 == 0 else ys[::-1]
            pos.append(np.stack([np.full_like(ys, x), ys, np.zeros_like(ys)], axis=1))
            yaw.append(np.full(ys.size, np.pi / 2 if k % 2 == 0 else -np.pi / 2))
    p = np.concatenate(pos)
    t = np.arange(len(p)) * step_m / speed_m_s
    return Trajectory(t, p, quat_from_yaw(np.concatenate(yaw)))
