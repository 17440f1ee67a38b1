"""``report.html``: one self-contained page a person opens offline in any browser, showing what a run found.

The B-scan with its detected boxes (kind and depth on each), the host eps_r from each method, depth slices of the
migrated volume and the noise map, an interactive 3D view (the strongest voxels as a point cloud, the extracted
targets named as in ``targets.json``, the antenna path), and the run's settings and provenance. The figures are
plotly's; its JavaScript is embedded once, so the page needs no network.
"""

from __future__ import annotations

import html
import json
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from gpr3d.core.errors import GPR3DError

__all__ = ["write_report"]

#: the most traces and samples of the B-scan drawn (a longer record is decimated for the page)
MAX_TRACES, MAX_SAMPLES = 1500, 400
#: the most voxels of the 3D point cloud
MAX_POINTS = 20_000


def _plotly():
    try:
        import plotly.graph_objects as go
        from plotly.offline import get_plotlyjs
        from plotly.subplots import make_subplots
    except ImportError:
        raise GPR3DError("the report needs plotly: pip install plotly") from None
    return go, make_subplots, get_plotlyjs


def _bscan_figure(go, survey, found):
    s = survey.dewow().remove_background() if survey.frequency_hz else survey.remove_background()
    step_t = max(1, int(np.ceil(s.n_traces / MAX_TRACES)))
    step_s = max(1, int(np.ceil(s.n_samples / MAX_SAMPLES)))
    img = s.data[::step_t, ::step_s].T
    clip = float(np.percentile(np.abs(img), 99)) or 1.0
    traces = np.arange(0, s.n_traces, step_t)
    t_ns = np.arange(0, s.n_samples, step_s) * s.dt_s * 1e9
    fig = go.Figure(go.Heatmap(z=img, x=traces, y=t_ns, colorscale="Greys", zmin=-clip, zmax=clip, showscale=False,
                               hovertemplate="trace %{x}<br>%{y:.2f} ns<extra></extra>"))
    shapes, notes = [], []
    for t in (found or {}).get("targets", []):
        b = t["box"]
        shapes.append(dict(type="rect", x0=b[0], x1=b[2], y0=b[1] * 1e9, y1=b[3] * 1e9,
                           line=dict(color="#e4572e", width=2)))
        label = t.get("kind") or "target"
        if t.get("depth_m") is not None:
            label += f" {t['depth_m']:.2f} m"
        notes.append(dict(x=b[0], y=b[1] * 1e9, text=label, showarrow=False, xanchor="left", yanchor="bottom",
                          font=dict(color="#e4572e", size=11)))
    # all at once: plotly checks the whole layout again at each add_shape / add_annotation (5 s for 99 boxes)
    fig.update_layout(shapes=shapes, annotations=notes)
    fig.update_yaxes(autorange="reversed", title="two-way time (ns)")
    fig.update_xaxes(title="trace")
    fig.update_layout(height=420, margin=dict(l=60, r=20, t=30, b=50),
                      title=f"B-scan ({s.n_traces} traces; dewow, background removed): "
                            f"{len((found or {}).get('targets', []))} detections")
    return fig


def _slices_figure(go, make_subplots, vol, n_slices: int = 3):
    g = vol.grid
    env = vol.arrays["envelope"]
    depths = g.d0 + g.dd * np.arange(g.nd)
    x = g.x0 + g.dx * np.arange(g.nx)
    y = g.y0 + g.dy * np.arange(g.ny)
    ks = np.linspace(0, g.nd - 1, n_slices + 2)[1:-1].round().astype(int)
    panels = [("max over depth", env.max(axis=2))] + [(f"depth {depths[k]:.2f} m", env[:, :, k]) for k in ks]
    if "noise_map" in vol.arrays:
        panels.append(("noise map (outside the boxes)", vol.arrays["noise_map"].max(axis=2)))
    fig = make_subplots(rows=1, cols=len(panels), subplot_titles=[p[0] for p in panels], horizontal_spacing=0.03)
    top = float(env.max()) or 1.0
    for c, (name, a) in enumerate(panels, 1):
        if g.ny == 1:  # one profile: show the vertical plane instead of a one-cell-wide map
            fig.add_trace(go.Heatmap(z=env[:, 0, :].T, x=x, y=depths, colorscale="Hot", showscale=False,
                                     zmin=0, zmax=top), row=1, col=c)
            fig.update_yaxes(autorange="reversed", row=1, col=c)
            break
        fig.add_trace(go.Heatmap(z=a.T, x=x, y=y, colorscale="Hot", showscale=False,
                                 zmin=0, zmax=float(a.max()) or 1.0), row=1, col=c)
        fig.update_yaxes(scaleanchor=f"x{c if c > 1 else ''}", row=1, col=c)
    fig.update_layout(height=360, margin=dict(l=40, r=20, t=40, b=40),
                      title="migrated envelope: top view and depth slices (x, y in metres)")
    return fig


def _world_xy(vol, config, xs, ys):
    frame = (config or {}).get("frame")
    if not frame:
        return xs, ys
    o, d = np.asarray(frame["origin_xy"], float), np.asarray(frame["direction_xy"], float)
    n = np.array([-d[1], d[0]])
    return o[0] + xs * d[0] + ys * n[0], o[1] + xs * d[1] + ys * n[1]


def _view3d_figure(go, vol, targets, positions, config):
    g = vol.grid
    env = vol.arrays["envelope"]
    cut = 0.5 * float(env.max())
    idx = np.argwhere(env > cut) if cut > 0 else np.zeros((0, 3), int)
    if len(idx) > MAX_POINTS:
        idx = idx[np.argsort(env[tuple(idx.T)])[-MAX_POINTS:]]
    xs, ys = _world_xy(vol, config, g.x0 + g.dx * idx[:, 0], g.y0 + g.dy * idx[:, 1])
    d = g.d0 + g.dd * idx[:, 2]
    fig = go.Figure(go.Scatter3d(x=xs, y=ys, z=-d, mode="markers", name="envelope > half its peak",
                                 marker=dict(size=2, color=env[tuple(idx.T)], colorscale="Hot", opacity=0.5)))
    for t in targets:
        p = np.asarray(t["points_xyz"], float)
        fig.add_trace(go.Scatter3d(x=p[:, 0], y=p[:, 1], z=-p[:, 2], mode="lines+markers+text", name=t["name"],
                                   text=[t["name"]] + [""] * (len(p) - 1), line=dict(width=8),
                                   marker=dict(size=5)))
    if positions is not None:
        step = max(1, len(positions) // 3000)
        p = positions[::step]
        fig.add_trace(go.Scatter3d(x=p[:, 0], y=p[:, 1], z=np.zeros(len(p)), mode="lines", name="antenna path",
                                   line=dict(color="#2e86ab", width=3)))
    fig.update_layout(height=560, margin=dict(l=0, r=0, t=30, b=0), title="3D view (drag to turn; z up, metres)",
                      scene=dict(aspectmode="data", xaxis_title="x (m)", yaxis_title="y (m)", zaxis_title="z (m)"))
    return fig


def _table(rows, header, table_id=""):
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr" + (f' data-name="{html.escape(str(r[0]))}"' if table_id == "targets" else "") + ">" +
                   "".join(f"<td>{html.escape(str(v))}</td>" for v in r) + "</tr>" for r in rows)
    return f'<table id="{table_id}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _eps_rows(found, config):
    rows = []
    p = (found or {}).get("permittivity") or {}
    for k in ("net", "fit"):
        if isinstance(p.get(k), dict) and p[k].get("eps_r") is not None:
            q = p[k]
            rows.append((k, f"{q['eps_r']:.2f}", f"{q.get('sigma_eps_r', float('nan')):.2f}"))
    if p.get("eps_r") is not None:
        rows.append((f"{p.get('method', 'combined')} (the estimate)", f"{p['eps_r']:.2f}",
                     f"{p.get('sigma_eps_r', float('nan')):.2f}"))
    if config:
        rows.append((f"used for the migration ({config.get('eps_r_source', '?')})", f"{config['eps_r']:.2f}", ""))
    return rows


_STYLE = """body{font-family:system-ui,sans-serif;margin:24px auto;max-width:1400px;color:#222}
h1{font-size:1.5em}h2{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #ccc;padding:3px 9px;text-align:left}
th{background:#f3f3f3}pre{background:#f7f7f7;padding:8px;overflow:auto;max-height:320px;font-size:12px}"""


def write_report(folder, *, out=None, survey=None, detections=None, reconstruction=None, title=None) -> Path:
    """Write ``report.html`` for a run folder (``gpr3d run``'s, or any with the same files).

    Parameters
    ----------
    folder : str or Path
        The run folder: ``survey.h5``, ``detections.json`` and ``reconstruction/`` are looked for in it.
    out : str or Path, optional
        The page (default ``folder/report.html``).
    survey, detections, reconstruction : str or Path, optional
        Other places of the survey (gpr3d ``.h5``), the detections (``gpr3d detect`` JSON) and the reconstruction
        folder (``gpr3d reconstruct``'s); each is left out of the page where it is absent.
    title : str, optional

    Returns
    -------
    Path
        The page written (atomically).

    Raises
    ------
    GPR3DError
        Without plotly, or when the folder holds none of the three.
    """
    import gpr3d
    from gpr3d import __version__
    from gpr3d.core.atomic import atomic_write_text

    go, make_subplots, get_plotlyjs = _plotly()
    folder = Path(folder)
    survey = Path(survey) if survey else folder / "survey.h5"
    detections = Path(detections) if detections else folder / "detections.json"
    reconstruction = Path(reconstruction) if reconstruction else folder / "reconstruction"
    have = [p for p in (survey, detections, reconstruction / "targets.json") if p.exists()]
    if not have:
        raise GPR3DError(f"{folder}: nothing to report (no survey.h5, detections.json or reconstruction/)")
    s = gpr3d.read(survey) if survey.exists() else None
    found = None
    if detections.exists():
        from gpr3d.io.detections import read_detections

        found = read_detections(detections)[0]
    targets, config, vol = [], None, None
    if (reconstruction / "targets.json").exists():
        from gpr3d.io.volume import read_volume

        targets = json.loads((reconstruction / "targets.json").read_text())["targets"]
        config = json.loads((reconstruction / "config.json").read_text())
        vol = read_volume(reconstruction / "volume.h5", names=None)
    figs, parts = [], []
    title = title or f"gpr3d report: {Path(str((found or {}).get('input') or survey)).name}"
    parts.append(f"<h1>{html.escape(title)}</h1><p>gpr3d {__version__}; written "
                 f"{datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}</p>")
    parts.append("<h2>Targets</h2>")
    rows = [(t["name"], t["kind"], f"{t['depth_m']:.2f}", f"{t.get('score', float('nan')):.2f}",
             "; ".join("(" + ", ".join(f"{v:.2f}" for v in p) + ")" for p in t["points_xyz"])) for t in targets]
    parts.append(_table(rows, ["name", "kind", "depth to top (m)", "score", "points x, y, depth (m)"], "targets")
                 if rows else '<p id="targets">no targets extracted</p>')
    parts.append("<h2>Host permittivity</h2>")
    eps = _eps_rows(found, config)
    parts.append(_table(eps, ["method", "eps_r", "+-"], "permittivity") if eps else "<p>no estimate</p>")
    if s is not None:
        parts.append("<h2>B-scan and detections</h2>")
        figs.append(("bscan", _bscan_figure(go, s, found)))
        parts.append("{bscan}")
    if vol is not None:
        parts.append("<h2>Depth slices and noise map</h2>")
        figs.append(("slices", _slices_figure(go, make_subplots, vol)))
        parts.append("{slices}")
        parts.append("<h2>3D view</h2>")
        figs.append(("view3d", _view3d_figure(go, vol, targets, None if s is None else s.positions_xyz, config)))
        parts.append("{view3d}")
    parts.append("<h2>Settings and provenance</h2>")
    prov = {"survey": None if s is None else {"file": str(survey), "n_traces": s.n_traces, "n_samples": s.n_samples,
                                              "dt_s": s.dt_s, "frequency_hz": s.frequency_hz,
                                              "positions": s.metadata.get("positions_source")},
            "reconstruction": config}
    if (folder / "run.json").exists():
        prov["run"] = json.loads((folder / "run.json").read_text())
    parts.append(f"<pre>{html.escape(json.dumps(prov, indent=1, default=str))}</pre>")
    body = "\n".join(parts)
    for name, fig in figs:
        body = body.replace("{" + name + "}", fig.to_html(full_html=False, include_plotlyjs=False,
                                                          div_id=f"fig-{name}", config={"responsive": True}))
    page = (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style><script>{get_plotlyjs()}</script></head><body>\n{body}\n</body></html>\n")
    path = Path(out) if out else folder / "report.html"
    atomic_write_text(path, page)
    return path
