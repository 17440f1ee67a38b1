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


#: split drawing: the first this many figures (top and front) drawn in the calling process, the others (the 3D view)
#: each in a process forked for it. Measured in the figures' process on the bench_stages survey (znver4, 2 cores,
#: medians of 12): 0.24 s; every figure forked 0.29 s; none 0.37 s
HERE = 2


def draw_figures(fi: FigureInputs, out, *, split: bool | None = None) -> list[str]:
    """The figures of :func:`reconstruction_figures` drawn from what :func:`figure_inputs` took; returns the file
    names written into ``out``.

    Parameters
    ----------
    fi : FigureInputs
        What to draw.
    out : str or Path
        The folder the figures are written into.
    split : bool or None
        Draw ``view3d.png`` in a process forked for it while this one draws ``top.png`` and ``front.png`` (the
        same files, in two thirds of the time on two cores; ``HERE``); a figure whose process could not be
        forked, or did not write it, is drawn here. None: split only in the figures' own process
        (:mod:`gpr3d.viz.worker`), which runs no thread (a process with threads is not forked).

    Returns
    -------
    list of str
        The names of the figures written.
    """
    from gpr3d.viz.worker import fork_job, in_worker, wait_job

    out = Path(out)
    jobs = [_top, _front, _view3d] if fi.frame is None else [_profile_map, _profile_section, _view3d]
    k = HERE if (in_worker() if split is None else split) else len(jobs)
    forked = [fork_job(job, fi, out) for job in jobs[k:]]
    for job, pid in zip(jobs[k:], forked):
        if pid is None:  # (no process to be had)
            job(fi, out)
    for job in jobs[:k]:
        job(fi, out)
    for job, pid in zip(jobs[k:], forked):
        if pid is not None and not wait_job(pid):  # (what it raised, raised here)
            job(fi, out)
    return ["front.png", "top.png", "view3d.png"]


# the views of a 3D image and the 3D view are laid out by hand (tight_layout measured a third of their time); a
# profile's map and section keep it

def _top(fi: FigureInputs, out) -> None:
    """``top.png`` of a 3D image: the envelope's maximum over depth with the targets (beside the noise map's)."""
    plt = pyplot()
    g, vmax, views = fi.grid, fi.vmax, fi.views
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
    save_figure(fig, out / "top.png", dpi=110, tight=False)


def _front(fi: FigureInputs, out) -> None:
    """``front.png`` of a 3D image: the envelope's maximum over y with the targets."""
    plt = pyplot()
    g = fi.grid
    fig, ax = plt.subplots(figsize=(8, 4))
    front = fi.views["front"]
    im = ax.imshow(front, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot",
                   interpolation=_interpolation(front), aspect="auto", vmin=0, vmax=fi.vmax)
    _envelope_colourbar(fig, im, ax, "max envelope")
    _mark(ax, fi.targets, lambda t: np.asarray(t.points_xyz)[:, [0, 2]])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("depth (m)")
    ax.set_title("front view: max envelope over y; cyan: extracted targets", fontsize=9)
    fig.subplots_adjust(left=0.1, right=0.9, bottom=0.13, top=0.92)
    save_figure(fig, out / "front.png", dpi=110, tight=False)


def _profile_map(fi: FigureInputs, out) -> None:
    """``top.png`` of a profile migrated in 2D: the map of the line with the targets."""
    plt = pyplot()
    g, frame = fi.grid, fi.frame
    fig, ax = plt.subplots(figsize=(6.8, 6))
    ends = frame.to_world([g.x[0], g.x[-1]])
    ax.plot(ends[:, 0], ends[:, 1], "k-", lw=1, label="profile (migrated in 2D)")
    _mark(ax, fi.targets, lambda t: np.asarray(t.points_xyz)[:, :2], colour="b")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("map: the profile and the targets on it", fontsize=9)
    save_figure(fig, out / "top.png", dpi=110)


def _profile_section(fi: FigureInputs, out) -> None:
    """``front.png`` of a profile migrated in 2D: the migrated section along it (the noise map's below)."""
    plt = pyplot()
    g, frame, views = fi.grid, fi.frame, fi.views
    n = len(views)
    fig, axes = plt.subplots(n, 1, figsize=(8, 3.6 * n), squeeze=False)
    for ax, (what, section) in zip(axes[:, 0], views.items()):
        im = ax.imshow(section.T, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot",
                       interpolation=_interpolation(section), aspect="auto", vmin=0, vmax=fi.vmax)
        _envelope_colourbar(fig, im, ax, what)
        ax.set_ylabel("depth (m)")
        ax.set_title(f"profile migrated in 2D: {what}" + ("; cyan: extracted targets" if what == "envelope"
                                                          else " (the removed data)"), fontsize=9)
    _mark(axes[0, 0], fi.targets, lambda t: np.column_stack([t.extra["along_m"], np.asarray(t.points_xyz)[:, 2]]))
    axes[-1, 0].set_xlabel(f"along the profile (m) from ({frame.origin_xy[0]:.2f}, {frame.origin_xy[1]:.2f}) "
                           f"towards ({frame.direction_xy[0]:+.2f}, {frame.direction_xy[1]:+.2f})")
    save_figure(fig, out / "front.png", dpi=110)


def _view3d(fi: FigureInputs, out) -> None:
    """``view3d.png``: the voxels above the threshold, coloured by their envelope, and the targets."""
    plt = pyplot()
    fig = plt.figure(figsize=(7.5, 6))
    ax = fig.add_subplot(projection="3d")
    mappable = _points_by_colour(ax, fi.points, fi.values)
    fig.colorbar(mappable, ax=ax, fraction=0.03, pad=0.08, label="envelope (image units)")
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
    save_figure(fig, out / "view3d.png", dpi=110, tight=False)


#: the 3D view's colours: the envelope's range cut into this many equal bins, each bin's points one marker line
#: in the colour of the bin's middle
COLOUR_BINS = 32


def _points_by_colour(ax, points, values, cmap="hot", bins: int = COLOUR_BINS):
    """Draw ``points`` on the 3D axes ``ax`` as round markers coloured by ``values``: one line of markers per colour
    bin, the dimmest first (Agg draws a line's markers from one stamp, about half the time of a scatter of
    the same points, whose every marker is a path of its own); returns the mappable for the colour bar."""
    import matplotlib as mpl
    from mpl_toolkits.mplot3d import art3d

    values = np.asarray(values, float)
    norm = mpl.colors.Normalize(float(values.min()), float(values.max())) if len(values) else mpl.colors.Normalize(0, 1)
    cm = mpl.colormaps[cmap]
    which = np.clip((norm(values).filled(0.0) * bins).astype(int), 0, bins - 1)
    for b in range(bins):
        m = which == b
        if m.any():
            ax.add_line(art3d.Line3D(points[m, 0], points[m, 1], points[m, 2], linestyle="none", marker="o",
                                     markersize=np.sqrt(2.0), markeredgewidth=0, color=cm((b + 0.5) / bins),
                                     alpha=0.5))
    if len(values):
        ax.auto_scale_xyz(points[:, 0], points[:, 1], points[:, 2], had_data=False)
    return mpl.cm.ScalarMappable(norm=norm, cmap=cm)
