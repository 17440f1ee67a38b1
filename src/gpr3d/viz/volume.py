"""Figures of a reconstruction: top and front views of the envelope with the extracted targets, the noise map,
and a 3D scatter of the voxels above the target threshold, each image with its colour bar and each target
labelled with its name in ``targets.json`` (``T1``, ``T2``, ...). A single profile migrated in 2D (see
:class:`~gpr3d.migration.reconstruct.ProfileFrame`) gets its map and its vertical section instead."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gpr3d.migration.targets import target_name
from gpr3d.viz._figures import pyplot, save_figure

__all__ = ["FigureInputs", "draw_figures", "figure_inputs", "reconstruction_figures"]

def _mark(ax, targets, xy_of, colour="c"):
    """Draw each target (line or point) with ``xy_of(target) -> (n, 2)`` and label it with its name."""
    for i, t in enumerate(targets):
        p = np.asarray(xy_of(t), float)
        ax.plot(p[:, 0], p[:, 1], f"{colour}-" if t.kind == "line" else f"{colour}o", lw=2, ms=5)
        ax.annotate(target_name(i), p.mean(axis=0), xytext=(4, 4), textcoords="offset points",
                    color="white" if colour == "c" else colour, fontsize=8, fontweight="bold", ha="left",
                    va="bottom", bbox=dict(boxstyle="round,pad=0.15", fc="black", alpha=0.55, lw=0)
                    if colour == "c" else None)


#: an image with no more cells than this along either side is drawn cell by cell ("nearest": each cell a block of
#: pixels, three times faster to draw than matplotlib's antialiasing, which only a larger image needs, where
#: several cells share a pixel and a thin target must not drop out)
NEAREST_UP_TO = 600


def _interpolation(a) -> str:
    return "nearest" if max(np.shape(a)) <= NEAREST_UP_TO else "antialiased"


def _envelope_colourbar(fig, im, ax, what="envelope"):
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03, label=f"{what} (image units)")


@dataclass
class FigureInputs:
    """What the figures of a reconstruction draw, taken from it by :func:`figure_inputs`: the views and the voxels
    above the threshold, not the volume (small enough to hand to another process, :mod:`gpr3d.viz.worker`)."""

    grid: object  #: the :class:`~gpr3d.core.grid.Grid3D` (a profile's own frame where ``frame`` is given)
    frame: object  #: the :class:`~gpr3d.migration.reconstruct.ProfileFrame` of a profile migrated in 2D, or None
    targets: list  #: the :class:`~gpr3d.migration.targets.Target3D` extracted
    vmax: float | None  #: the colour scale's top (the 99.9th percentile of the top view)
    views: dict  #: a 3D image: ``top``, ``front`` (and ``noise``: the noise map's top view); a profile: ``envelope``
    #: (and ``noise map``): the section under it
    points: np.ndarray  #: ``(n, 3)`` world points of the voxels above the target threshold (20,000 at most)
    values: np.ndarray  #: the envelope at those voxels


def figure_inputs(rec) -> FigureInputs:
    """The views and points that :func:`draw_figures` draws, from a
    :class:`~gpr3d.migration.reconstruct.Reconstruction` (its envelope's maxima over depth and over y, or a
    profile's section, the noise map's alike, and the voxels above ``threshold`` x the 99.5th percentile of the
    top view, 20,000 of them at most, drawn at random with a fixed seed)."""
    env = rec.envelope
    top = env.max(axis=2)
    if rec.frame is None:
        views = {"top": top.T, "front": env.max(axis=1).T}
        if rec.noise_map is not None:
            views["noise"] = rec.noise_map.max(axis=2).T
    else:
        views = {"envelope": env[:, 0, :]}
        if rec.noise_map is not None:
            views["noise map"] = rec.noise_map[:, 0, :]
    thr = rec.config["threshold"] * float(np.percentile(top, 99.5))
    idx = np.argwhere(env >= thr)
    if len(idx) > 20000:
        idx = idx[np.random.default_rng(0).choice(len(idx), 20000, replace=False)]
    return FigureInputs(grid=rec.grid, frame=rec.frame, targets=list(rec.targets),
                        vmax=float(np.percentile(top, 99.9)) or None, views=views, points=rec.world_points(idx),
                        values=env[tuple(idx.T)])


def reconstruction_figures(rec, out) -> list[str]:
    """``top.png`` (the envelope's maximum over depth, with the targets, beside the noise map where there is one),
    ``front.png`` (maximum over y) and ``view3d.png`` (voxels above the target threshold and the targets) of a
    :class:`~gpr3d.migration.reconstruct.Reconstruction`, written into ``out``; returns the file names. For a
    profile migrated in 2D, ``top.png`` is the map of the line with the targets and ``front.png`` the migrated
    section along it. (:func:`figure_inputs`, then :func:`draw_figures`.)"""
    return draw_figures(figure_inputs(rec), out)


def draw_figures(fi: FigureInputs, out) -> list[str]:
    """The figures of :func:`reconstruction_figures` drawn from what :func:`figure_inputs` took; returns the file
    names written into ``out``."""
    plt = pyplot()
    out = Path(out)
    g, frame, vmax, views = fi.grid, fi.frame, fi.vmax, fi.views
    figs = {}
    if frame is None:
        ext_xy = (g.x[0], g.x[-1], g.y[0], g.y[-1])
        top = views["top"]
        n = 2 if "noise" in views else 1
        fig, axes = plt.subplots(1, n, figsize=(6.8 * n, 6), squeeze=False)
        axes = axes[0]
        im = axes[0].imshow(top, origin="lower", extent=ext_xy, cmap="hot", aspect="equal", vmin=0, vmax=vmax,
                            interpolation=_interpolation(top))
        _envelope_colourbar(fig, im, axes[0], "max envelope")
        _mark(axes[0], fi.targets, lambda t: np.asarray(t.points_xyz)[:, :2])
        axes[0].set_title("top view: max envelope over depth; cyan: extracted targets", fontsize=9)
        axes[0].set_xlabel("x (m)")
        axes[0].set_ylabel("y (m)")
        if "noise" in views:
            im = axes[1].imshow(views["noise"], origin="lower", extent=ext_xy, cmap="hot",
                                aspect="equal", vmin=0, vmax=vmax, interpolation=_interpolation(top))
            _envelope_colourbar(fig, im, axes[1], "max envelope")
            axes[1].set_title("noise map: the removed data, migrated (same colour scale)", fontsize=9)
            axes[1].set_xlabel("x (m)")
        fig.subplots_adjust(left=0.1 / n, right=1 - 0.11 / n, bottom=0.08, top=0.95, wspace=0.4)
        figs["top.png"] = fig
        fig, ax = plt.subplots(figsize=(8, 4))
        front = views["front"]
        im = ax.imshow(front, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot",
                       interpolation=_interpolation(front),
                       aspect="auto", vmin=0, vmax=vmax)
        _envelope_colourbar(fig, im, ax, "max envelope")
        _mark(ax, fi.targets, lambda t: np.asarray(t.points_xyz)[:, [0, 2]])
        ax.set_xlabel("x (m)")
        ax.set_ylabel("depth (m)")
        ax.set_title("front view: max envelope over y; cyan: extracted targets", fontsize=9)
        fig.subplots_adjust(left=0.1, right=0.9, bottom=0.13, top=0.92)
        figs["front.png"] = fig
    else:
        fig, ax = plt.subplots(figsize=(6.8, 6))
        ends = frame.to_world([g.x[0], g.x[-1]])
        ax.plot(ends[:, 0], ends[:, 1], "k-", lw=1, label="profile (migrated in 2D)")
        _mark(ax, fi.targets, lambda t: np.asarray(t.points_xyz)[:, :2], colour="b")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(loc="best", fontsize=8)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title("map: the profile and the targets on it", fontsize=9)
        figs["top.png"] = fig
        n = len(views)
        fig, axes = plt.subplots(n, 1, figsize=(8, 3.6 * n), squeeze=False)
        for ax, (what, section) in zip(axes[:, 0], views.items()):
            im = ax.imshow(section.T, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot",
                           interpolation=_interpolation(section),
                           aspect="auto", vmin=0, vmax=vmax)
            _envelope_colourbar(fig, im, ax, what)
            ax.set_ylabel("depth (m)")
            ax.set_title(f"profile migrated in 2D: {what}" + ("; cyan: extracted targets" if what == "envelope"
                                                              else " (the removed data)"), fontsize=9)
        _mark(axes[0, 0], fi.targets, lambda t: np.column_stack([t.extra["along_m"],
                                                                  np.asarray(t.points_xyz)[:, 2]]))
        axes[-1, 0].set_xlabel(f"along the profile (m) from ({frame.origin_xy[0]:.2f}, {frame.origin_xy[1]:.2f}) "
                               f"towards ({frame.direction_xy[0]:+.2f}, {frame.direction_xy[1]:+.2f})")
        figs["front.png"] = fig
    fig = plt.figure(figsize=(7.5, 6))
    ax = fig.add_subplot(projection="3d")
    pts = fi.points
    sc = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=fi.values, cmap="hot", s=2, alpha=0.5)
    fig.colorbar(sc, ax=ax, fraction=0.03, pad=0.08, label="envelope (image units)")
    for i, t in enumerate(fi.targets):
        p = np.array(t.points_xyz)
        ax.plot(p[:, 0], p[:, 1], -p[:, 2], "b-" if t.kind == "line" else "bo", lw=3)
        c = p.mean(axis=0)
        ax.text(c[0], c[1], -c[2], target_name(i), color="blue", fontsize=8, fontweight="bold")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title("3D: voxels above the threshold, extracted targets (blue)", fontsize=9)
    fig.subplots_adjust(left=0.0, right=0.9, bottom=0.03, top=0.94)
    figs["view3d.png"] = fig
    # the views of a 3D image and the 3D scatter are laid out above (tight_layout measured a third of their time);
    # a profile's map and section keep it
    fixed = {"view3d.png"} | ({"top.png", "front.png"} if frame is None else set())
    for name, f in figs.items():
        save_figure(f, out / name, dpi=110, tight=name not in fixed)
    return sorted(figs)
