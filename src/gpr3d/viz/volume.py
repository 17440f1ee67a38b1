"""Figures of a reconstruction: top and front views of the envelope with the extracted targets, the noise map,
and a 3D scatter of the voxels above the target threshold, each image with its colour bar and each target
labelled with its name in ``targets.json`` (``T1``, ``T2``, ...). A single profile migrated in 2D (see
:class:`~gpr3d.migration.reconstruct.ProfileFrame`) gets its map and its vertical section instead."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpr3d.migration.targets import target_name
from gpr3d.viz._figures import pyplot, save_figure

__all__ = ["reconstruction_figures"]

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


def reconstruction_figures(rec, out) -> list[str]:
    """``top.png`` (the envelope's maximum over depth, with the targets, beside the noise map where there is one),
    ``front.png`` (maximum over y) and ``view3d.png`` (voxels above the target threshold and the targets) of a
    :class:`~gpr3d.migration.reconstruct.Reconstruction`, written into ``out``; returns the file names. For a
    profile migrated in 2D, ``top.png`` is the map of the line with the targets and ``front.png`` the migrated
    section along it."""
    plt = pyplot()
    out = Path(out)
    g, env = rec.grid, rec.envelope
    frame = rec.frame
    figs = {}
    vmax = float(np.percentile(env.max(axis=2), 99.9)) or None
    if frame is None:
        ext_xy = (g.x[0], g.x[-1], g.y[0], g.y[-1])
        n = 2 if rec.noise_map is not None else 1
        fig, axes = plt.subplots(1, n, figsize=(6.8 * n, 6), squeeze=False)
        axes = axes[0]
        top = env.max(axis=2).T
        im = axes[0].imshow(top, origin="lower", extent=ext_xy, cmap="hot", aspect="equal", vmin=0, vmax=vmax,
                            interpolation=_interpolation(top))
        _envelope_colourbar(fig, im, axes[0], "max envelope")
        _mark(axes[0], rec.targets, lambda t: np.asarray(t.points_xyz)[:, :2])
        axes[0].set_title("top view: max envelope over depth; cyan: extracted targets", fontsize=9)
        axes[0].set_xlabel("x (m)")
        axes[0].set_ylabel("y (m)")
        if rec.noise_map is not None:
            im = axes[1].imshow(rec.noise_map.max(axis=2).T, origin="lower", extent=ext_xy, cmap="hot",
                                aspect="equal", vmin=0, vmax=vmax, interpolation=_interpolation(top))
            _envelope_colourbar(fig, im, axes[1], "max envelope")
            axes[1].set_title("noise map: the removed data, migrated (same colour scale)", fontsize=9)
            axes[1].set_xlabel("x (m)")
        fig.subplots_adjust(left=0.1 / n, right=1 - 0.11 / n, bottom=0.08, top=0.95, wspace=0.4)
        figs["top.png"] = fig
        fig, ax = plt.subplots(figsize=(8, 4))
        front = env.max(axis=1).T
        im = ax.imshow(front, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot",
                       interpolation=_interpolation(front),
                       aspect="auto", vmin=0, vmax=vmax)
        _envelope_colourbar(fig, im, ax, "max envelope")
        _mark(ax, rec.targets, lambda t: np.asarray(t.points_xyz)[:, [0, 2]])
        ax.set_xlabel("x (m)")
        ax.set_ylabel("depth (m)")
        ax.set_title("front view: max envelope over y; cyan: extracted targets", fontsize=9)
        fig.subplots_adjust(left=0.1, right=0.9, bottom=0.13, top=0.92)
        figs["front.png"] = fig
    else:
        fig, ax = plt.subplots(figsize=(6.8, 6))
        ends = frame.to_world([g.x[0], g.x[-1]])
        ax.plot(ends[:, 0], ends[:, 1], "k-", lw=1, label="profile (migrated in 2D)")
        _mark(ax, rec.targets, lambda t: np.asarray(t.points_xyz)[:, :2], colour="b")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(loc="best", fontsize=8)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title("map: the profile and the targets on it", fontsize=9)
        figs["top.png"] = fig
        n = 2 if rec.noise_map is not None else 1
        fig, axes = plt.subplots(n, 1, figsize=(8, 3.6 * n), squeeze=False)
        for ax, vol, what in zip(axes[:, 0], (env, rec.noise_map), ("envelope", "noise map")):
            im = ax.imshow(vol[:, 0, :].T, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot",
                           interpolation=_interpolation(vol[:, 0, :]),
                           aspect="auto", vmin=0, vmax=vmax)
            _envelope_colourbar(fig, im, ax, what)
            ax.set_ylabel("depth (m)")
            ax.set_title(f"profile migrated in 2D: {what}" + ("; cyan: extracted targets" if what == "envelope"
                                                              else " (the removed data)"), fontsize=9)
        _mark(axes[0, 0], rec.targets, lambda t: np.column_stack([t.extra["along_m"],
                                                                   np.asarray(t.points_xyz)[:, 2]]))
        axes[-1, 0].set_xlabel(f"along the profile (m) from ({frame.origin_xy[0]:.2f}, {frame.origin_xy[1]:.2f}) "
                               f"towards ({frame.direction_xy[0]:+.2f}, {frame.direction_xy[1]:+.2f})")
        figs["front.png"] = fig
    fig = plt.figure(figsize=(7.5, 6))
    ax = fig.add_subplot(projection="3d")
    thr = rec.config["threshold"] * float(np.percentile(env.max(axis=2), 99.5))
    idx = np.argwhere(env >= thr)
    if len(idx) > 20000:
        idx = idx[np.random.default_rng(0).choice(len(idx), 20000, replace=False)]
    pts = rec.world_points(idx)
    sc = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=env[tuple(idx.T)], cmap="hot", s=2, alpha=0.5)
    fig.colorbar(sc, ax=ax, fraction=0.03, pad=0.08, label="envelope (image units)")
    for i, t in enumerate(rec.targets):
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
