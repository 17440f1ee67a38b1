"""Figures of a 3D reconstruction: top and front views of the envelope with the extracted targets, the noise
map, and a 3D scatter of the voxels above the target threshold."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gpr3d.viz._figures import pyplot, save_figure

__all__ = ["reconstruction_figures"]


def reconstruction_figures(rec, out) -> list[str]:
    """``top.png`` (the envelope's maximum over depth, with the targets, beside the noise map where there is one),
    ``front.png`` (maximum over y) and ``view3d.png`` (voxels above the target threshold and the targets) of a
    :class:`~gpr3d.migration.reconstruct.Reconstruction`, written into ``out``; returns the file names."""
    plt = pyplot()
    out = Path(out)
    g, env = rec.grid, rec.envelope
    ext_xy = (g.x[0], g.x[-1], g.y[0], g.y[-1])
    figs = {}
    fig, axes = plt.subplots(1, 2 if rec.noise_map is not None else 1, figsize=(12 if rec.noise_map
                                                                                      is not None else 6.5, 6))
    axes = np.atleast_1d(axes)
    axes[0].imshow(env.max(axis=2).T, origin="lower", extent=ext_xy, cmap="hot", aspect="equal")
    for t in rec.targets:
        p = np.array(t.points_xyz)
        axes[0].plot(p[:, 0], p[:, 1], "c-" if t.kind == "line" else "co", lw=2, ms=5)
    axes[0].set_title("top view: max envelope over depth; cyan: extracted targets", fontsize=9)
    axes[0].set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    if rec.noise_map is not None:
        axes[1].imshow(rec.noise_map.max(axis=2).T, origin="lower", extent=ext_xy, cmap="hot", aspect="equal")
        axes[1].set_title("noise map: the removed data, migrated", fontsize=9)
        axes[1].set_xlabel("x (m)")
    figs["top.png"] = fig
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.imshow(env.max(axis=1).T, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot", aspect="auto")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("depth (m)")
    ax.set_title("front view: max envelope over y", fontsize=9)
    figs["front.png"] = fig
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    thr = rec.config["threshold"] * float(np.percentile(env.max(axis=2), 99.5))
    idx = np.argwhere(env >= thr)
    if len(idx) > 20000:
        idx = idx[np.random.default_rng(0).choice(len(idx), 20000, replace=False)]
    pts = g.points(idx)
    ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=env[tuple(idx.T)], cmap="hot", s=2, alpha=0.5)
    for t in rec.targets:
        p = np.array(t.points_xyz)
        ax.plot(p[:, 0], p[:, 1], -p[:, 2], "b-" if t.kind == "line" else "bo", lw=3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title("3D: voxels above the threshold, extracted targets (blue)", fontsize=9)
    figs["view3d.png"] = fig
    for name, f in figs.items():
        save_figure(f, out / name, dpi=110)
    return sorted(figs)
