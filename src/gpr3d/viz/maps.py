"""Plan views: antenna paths over the buried targets."""

from __future__ import annotations

import numpy as np

from gpr3d.viz._figures import plot_to_png, pyplot

__all__ = ["plot_survey_map", "save_survey_map_png", "plot_paths", "save_paths_png", "save_cscan_sheet"]


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


def save_cscan_sheet(path, cs, *, max_panels: int = 12, ncols: int = 4, dpi: int = 110, title=None) -> None:
    """A sheet of C-scan panels (at most ``max_panels``, spread over the slices), each with its time or depth
    window, each scaled to its own 99th percentile (deep slices are weaker: no gain is assumed), with one colour
    bar; written atomically."""
    from gpr3d.viz._figures import save_figure

    n = cs.values.shape[0]
    pick = np.unique(np.linspace(0, n - 1, min(n, max_panels)).round().astype(int))
    ncols = min(ncols, len(pick))
    rows = int(np.ceil(len(pick) / ncols))
    plt = pyplot()
    ext = (cs.x[0] - cs.cell_m / 2, cs.x[-1] + cs.cell_m / 2, cs.y[0] - cs.cell_m / 2, cs.y[-1] + cs.cell_m / 2)
    aspect = (ext[3] - ext[2]) / max(ext[1] - ext[0], 1e-9)
    fig, axes = plt.subplots(rows, ncols, figsize=(3.8 * ncols + 1.0, max(3.8 * aspect, 1.2) * rows + 0.9),
                             squeeze=False, layout="constrained")
    im = None
    for ax, k in zip(axes.flat, pick):
        v = cs.values[k]
        finite = v[np.isfinite(v)]
        scale = float(np.percentile(finite, 99)) if finite.size else 1.0
        im = ax.imshow((v / (scale or 1.0)).T, origin="lower", extent=ext, cmap="viridis", vmin=0, vmax=1)
        t0, t1 = cs.t_start_s[k] * 1e9, (cs.t_start_s[k] + cs.window_s) * 1e9
        label = f"{t0:.0f}-{t1:.0f} ns"
        if cs.depth_m is not None:
            label += f"  (~{cs.depth_m[k]:.2f} m)"
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(pick):]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axes.ravel().tolist(), shrink=0.8, label="mean envelope / the slice's 99th percentile")
    if title:
        fig.suptitle(title)
    save_figure(fig, path, dpi=dpi)
