"""Plan views: antenna paths over the buried targets."""

from __future__ import annotations

import numpy as np

from gpr3d.viz._figures import plot_to_png, pyplot

__all__ = ["plot_survey_map", "save_survey_map_png", "plot_paths", "save_paths_png"]


def plot_survey_map(positions_xyz, ax=None, *, pipes=(), spheres=(), title=None, color_by=None):
    """Antenna path (top view) with pipes (segments) and spheres; returns the axes."""
    import matplotlib

    if ax is None:
        _, ax = pyplot().subplots(figsize=(6, 6))
    p = np.asarray(positions_xyz)
    c = np.arange(len(p)) if color_by is None else color_by
    sc = ax.scatter(p[:, 0], p[:, 1], c=c, s=1.5, cmap="viridis")
    ax.figure.colorbar(sc, ax=ax, fraction=0.04, pad=0.02, label="trace" if color_by is None else "")
    for pipe in pipes:
        ax.plot([pipe.p0[0], pipe.p1[0]], [pipe.p0[1], pipe.p1[1]], color="crimson",
                lw=max(1.5, 200 * pipe.radius_m), solid_capstyle="round",
                label=f"pipe r = {pipe.radius_m * 100:.0f} cm, top {-max(pipe.p0[2], pipe.p1[2]) - pipe.radius_m:.2f} m deep")
    for s in spheres:
        ax.add_patch(matplotlib.patches.Circle(s.centre[:2], s.radius_m, color="orange", alpha=0.8))
    lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
    pad = 0.05 * (hi - lo).max()
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if pipes:
        ax.legend(loc="upper right", fontsize=7)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def save_survey_map_png(path, positions_xyz, *, dpi=120, **kwargs) -> None:
    plot_to_png(path, plot_survey_map, positions_xyz, figsize=(6.5, 6), dpi=dpi, **kwargs)


def plot_paths(paths: dict, ax=None, *, title=None):
    """Top views of several paths (name -> (n, 3) positions) on one axes, e.g. truth, odometry and fused."""
    if ax is None:
        _, ax = pyplot().subplots(figsize=(6, 6))
    styles = ["k-", "C3--", "C0-", "C2:", "C1-."]
    for (name, p), st in zip(paths.items(), styles * 3):
        p = np.asarray(p)
        ax.plot(p[:, 0], p[:, 1], st, lw=1.2, label=name)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(loc="best", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def save_paths_png(path, paths: dict, *, dpi=120, **kwargs) -> None:
    plot_to_png(path, plot_paths, paths, figsize=(6.5, 6), dpi=dpi, **kwargs)
