"""B-scan figures: time or depth axis, grey/'hot'/seismic colour maps, optional boxes."""

from __future__ import annotations

import numpy as np

from gpr3d.viz._figures import plot_to_png, pyplot

__all__ = ["plot_bscan", "save_bscan_png", "check_plot_args", "save_profile_png", "plot_wiggles", "plot_ascan",
           "save_label_preview"]


def check_plot_args(*, cmap=None, clip_percentile=None, axis=None) -> None:
    """One line naming a colour map matplotlib does not have, a clip percentile outside (0, 100], or an unknown
    axis (before any drawing)."""
    from gpr3d.core.errors import InvalidDataError

    if cmap is not None:
        import matplotlib

        if not isinstance(cmap, str) or cmap not in matplotlib.colormaps:
            raise InvalidDataError(f"colour map {cmap!r} is not one matplotlib knows (e.g. gray, hot, seismic, viridis)")
    if clip_percentile is not None:
        if isinstance(clip_percentile, bool) or not isinstance(clip_percentile, (int, float)) \
                or not 0 < clip_percentile <= 100:
            raise InvalidDataError(f"clip percentile must be in (0, 100], got {clip_percentile!r}")
    if axis is not None and axis not in ("time", "depth"):
        raise InvalidDataError(f"axis must be 'time' or 'depth', got {axis!r}")


def plot_bscan(
    survey,
    ax=None,
    *,
    axis: str = "time",
    eps_r: float | None = None,
    cmap: str = "gray",
    clip_percentile: float = 99.0,
    envelope: bool = False,
    boxes=None,
    apexes=None,
    title: str | None = None,
    box_labels=None,
    truth_boxes=None,
):
    """Draw ``survey`` as an image on ``ax`` (created if None).

    Parameters
    ----------
    survey : Survey
        The B-scan.
    ax : matplotlib.axes.Axes, optional
        Where to draw; default: a new figure's axes.
    axis : {"time", "depth"}
        ``time``: two-way time below time zero (ns); ``depth``: m, with ``eps_r`` or the survey's hint (a second
        axis shows the time).
    eps_r : float, optional
        The permittivity of the depth axis (default: the survey's).
    cmap : str
        Any matplotlib colour map; ``"hot"`` matches the reference paper's figures (it shows absolute amplitude).
    clip_percentile : float
        Colour limits at this percentile of the absolute amplitude.
    envelope : bool
        Draw the envelope (the analytic signal's magnitude along time) instead of the amplitude.
    boxes : iterable, optional
        ``(trace_start, t_start_s, trace_end, t_end_s)`` to outline.
    apexes : iterable, optional
        ``(trace, t_s)`` (times from the first sample) to mark with a cross.
    title : str, optional
        The axes' title.
    box_labels : list of str, optional
        A text per box (e.g. its kind and score), written above it.
    truth_boxes : iterable, optional
        Boxes like ``boxes`` drawn dashed in yellow (the labels, to compare).

    Returns
    -------
    matplotlib.axes.Axes
        The axes drawn on.

    Raises
    ------
    ValueError
        An unknown axis.
    InvalidDataError
        A colour map, clip or axis that cannot be used (before anything is drawn), a depth axis without eps_r, or
        another number of box labels than boxes.
    """
    check_plot_args(cmap=cmap, clip_percentile=clip_percentile, axis=axis)
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 4.5))
    img = survey.data.T.astype(np.float64)
    one_sided = cmap in ("hot", "afmhot", "gist_heat", "inferno", "magma") or envelope
    if envelope:  # the instantaneous amplitude: |analytic signal| along time, one smooth lobe per echo
        from scipy.signal import hilbert

        img = np.abs(hilbert(img, axis=0))
    elif one_sided:
        img = np.abs(img)
    lim = float(np.percentile(np.abs(img), clip_percentile)) or 1.0
    vmin, vmax = (0.0, lim) if one_sided else (-lim, lim)
    twt = survey.twt_s
    x = survey.distances_m
    xlabel = "distance along path (m)"
    if x is None or x[-1] <= 0:
        x = np.arange(survey.n_traces, dtype=float)
        xlabel = "trace"
    if axis == "depth":
        d = survey.depths_m(eps_r)
        y0, y1, ylabel = d[0], d[-1], f"depth (m), eps_r = {eps_r or survey.eps_r:.3g}"
    elif axis == "time":
        y0, y1, ylabel = twt[0] * 1e9, twt[-1] * 1e9, "two-way time (ns)"
    else:
        raise ValueError(f"axis must be 'time' or 'depth', got {axis!r}")
    im = ax.imshow(img, aspect="auto", cmap=cmap, vmin=vmin, vmax=vmax, extent=(x[0], x[-1], y1, y0),
                   interpolation="nearest")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title, fontsize=10)
    from matplotlib.patches import Rectangle

    def outline(b, **style):
        i0, t0, i1, t1 = b[:4]
        xa = np.interp([i0, i1], np.arange(survey.n_traces), x)
        if axis == "depth":
            ya = np.interp(np.array([t0, t1]), survey.times_s, survey.depths_m(eps_r))
        else:
            ya = (np.array([t0, t1]) - survey.t0_s) * 1e9
        ax.add_patch(Rectangle((xa[0], ya[0]), xa[1] - xa[0], ya[1] - ya[0], fill=False, **style))
        return xa[0], ya[0]

    for b in truth_boxes if truth_boxes is not None else ():
        outline(b, ec="yellow", lw=1.0, ls="--")
    if box_labels is not None and (boxes is None or len(box_labels) != len(boxes)):
        from gpr3d.core.errors import InvalidDataError

        raise InvalidDataError(f"{len(box_labels)} box labels for {0 if boxes is None else len(boxes)} boxes")
    for k, b in enumerate(boxes if boxes is not None else ()):
        xa, ya = outline(b, ec="cyan", lw=1.2)
        if box_labels is not None:
            ax.text(xa, ya, str(box_labels[k]), color="cyan", fontsize=6, va="bottom", ha="left")
    if apexes is not None:
        for tr, ts in apexes:
            xa = float(np.interp(tr, np.arange(survey.n_traces), x))
            ya = (float(np.interp(ts, survey.times_s, survey.depths_m(eps_r))) if axis == "depth"
                  else (ts - survey.t0_s) * 1e9)
            ax.plot([xa], [ya], marker="+", color="lime", ms=12, mew=1.5)
    ax.figure.colorbar(im, ax=ax, fraction=0.04, pad=0.02,
                       label="envelope" if envelope else "|amplitude|" if one_sided else "amplitude")
    return ax


def save_bscan_png(survey, path, *, dpi: int = 120, **kwargs) -> None:
    """Render :func:`plot_bscan` to a PNG file atomically.

    Parameters
    ----------
    survey : Survey
        The B-scan.
    path : str or Path
        The PNG written (nothing is left there if drawing fails).
    dpi : int
        Resolution.
    **kwargs
        Options of :func:`plot_bscan`.
    """
    plot_to_png(path, plot_bscan, survey, figsize=(8, 4.5), dpi=dpi, **kwargs)


def save_profile_png(path, prof, *, title=None, dpi: int = 110) -> None:
    """A migrated profile beside its envelope, depth down, each with a colour bar; written atomically."""
    from scipy.signal import hilbert

    from gpr3d.viz._figures import save_figure

    plt = pyplot()
    img = np.asarray(prof.image, dtype=np.float64)
    env = np.abs(hilbert(img, axis=1))
    ext = (prof.along_m[0], prof.along_m[-1], prof.depth_m[-1], prof.depth_m[0])
    fig, axes = plt.subplots(2, 1, figsize=(9, 7), layout="constrained")
    lim = float(np.percentile(np.abs(img), 99.5)) or 1.0
    for ax, data, cmap, vmin, vmax, label in ((axes[0], img, "seismic", -lim, lim, "migrated amplitude"),
                                              (axes[1], env, "viridis", 0.0,
                                               float(np.percentile(env, 99.5)) or 1.0, "envelope")):
        im = ax.imshow(data.T, aspect="auto", extent=ext, cmap=cmap, vmin=vmin, vmax=vmax)
        ax.set(xlabel="along the profile (m)", ylabel="depth (m)")
        fig.colorbar(im, ax=ax, label=label)
    axes[0].set_title(title or f"{prof.method} migration, eps_r {prof.eps_r:g}")
    save_figure(fig, path, dpi=dpi)


def plot_wiggles(survey, ax=None, *, traces=None, scale: float = 1.0, fill: bool = True, title=None):
    """Wiggle plot: each trace drawn as a curve about its own axis (time down), positive lobes filled; ``traces``
    picks which (default: at most 60, evenly spread); ``scale`` in trace spacings per the largest amplitude."""
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 5))
    n = survey.n_traces
    idx = np.unique(np.linspace(0, n - 1, min(n, 60)).round().astype(int)) if traces is None \
        else np.asarray(traces, dtype=int)
    if idx.size == 0 or idx.min() < 0 or idx.max() >= n:
        from gpr3d.core.errors import InvalidDataError

        raise InvalidDataError(f"traces must lie in 0..{n - 1}")
    t = (np.arange(survey.n_samples) * survey.dt_s - survey.t0_s) * 1e9
    data = survey.data[idx].astype(np.float64)
    peak = float(np.abs(data).max()) or 1.0
    gap = float(np.median(np.diff(idx))) if idx.size > 1 else 1.0
    for k, tr in zip(idx, data):
        x = k + scale * gap * tr / peak
        ax.plot(x, t, "k-", lw=0.5)
        if fill:
            ax.fill_betweenx(t, k, x, where=x > k, color="k", lw=0)
    ax.set(xlabel="trace", ylabel="two-way time (ns)", ylim=(t[-1], t[0]), title=title)
    return ax


def plot_ascan(survey, trace: int, ax=None, *, envelope: bool = True, title=None):
    """One A-scan: amplitude against two-way time, with its envelope."""
    from scipy.signal import hilbert

    from gpr3d.core.errors import InvalidDataError

    if not 0 <= int(trace) < survey.n_traces:
        raise InvalidDataError(f"trace must lie in 0..{survey.n_traces - 1}, got {trace}")
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 3.5))
    t = (np.arange(survey.n_samples) * survey.dt_s - survey.t0_s) * 1e9
    a = survey.data[int(trace)].astype(np.float64)
    ax.plot(t, a, "k-", lw=0.8, label="amplitude")
    if envelope:
        ax.plot(t, np.abs(hilbert(a)), "r-", lw=0.8, label="envelope")
        ax.legend(loc="upper right")
    ax.set(xlabel="two-way time (ns)", ylabel="amplitude", title=title or f"trace {int(trace)}")
    return ax


def save_label_preview(survey, labels: dict, path, *, title: str | None = None) -> None:
    """A labelled sample's B-scan (mean trace removed) with every visible label's box and apex drawn on it.

    Parameters
    ----------
    survey : Survey
        The sample's B-scan.
    labels : dict
        Its ``labels.json`` (:func:`gpr3d.simulation.packed.load_sample`): ``labels`` with ``box``, ``apex_trace``,
        ``apex_time_s``, ``kind``, ``depth_m`` and ``visible``.
    path : str or Path
        The PNG written.
    title : str, optional
        Instead of the kinds and depths of the labels.
    """
    labs = [lab for lab in labels["labels"] if lab["visible"]]
    kinds = ", ".join(f"{lab['kind']} {lab['depth_m'] * 100:.0f} cm" for lab in labs)
    save_bscan_png(survey.remove_background(), path, cmap="seismic", boxes=[lab["box"] for lab in labs],
                   apexes=[(lab["apex_trace"], lab["apex_time_s"]) for lab in labs],
                   title=title or f"labels (box, + apex): {kinds}; eps_r {labels.get('eps_r', survey.eps_r):.3g}")
