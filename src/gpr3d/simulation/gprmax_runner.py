"""Run a :class:`~gpr3d.simulation.scene.Scene` through gprMax 4 (Python API) as a 2D B-scan.

gprMax frame: x along the line, y vertical (up), z across (the invariant axis of a
2D TM model). The surface lies at ``y = scene.depth_m``; the model spans
``y = 0 .. depth_m + air_m``. Sources are z-directed Hertzian dipoles (broadside to
the line) with a Ricker pulse, on the surface; the receiver records ``Ez``.
Each trace is one gprMax model (the source and receiver step along x), the
outputs are merged with gprMax's own merge tool and read back as a Survey.
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import math
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from gpr3d.core.deps import require
from gpr3d.core.units import C0
from gpr3d.simulation.scene import MATERIALS, Scene

__all__ = ["build_gprmax_scene", "run_gprmax", "run_gprmax_following", "following_domain", "following_cost"]

INF = float("inf")
PML_CELLS = 10  #: gprMax's default PML thickness (cells), inside the model's edges


def _mat_id(name: str) -> str:
    return "pec" if name == "pec" else f"m_{name}"


def build_gprmax_scene(scene: Scene, *, x0: float = 0.0, width: float | None = None, air: float | None = None,
                       tx_x: float | None = None, rx_x: float | None = None):
    """A ``gprMax.Scene`` for the first trace (with source/receiver steps for the rest).

    With ``width`` the model covers only world ``x0 .. x0 + width`` (host everywhere in
    it, targets clipped to it), holds one trace with the transmitter and receiver at
    world ``tx_x`` / ``rx_x``, and has no steps: the antenna-following domain of
    :func:`run_gprmax_following`. ``air`` overrides the air above the surface.
    """
    g = require("gprMax")
    bad = [t.kind for t in scene.targets if not t.crosses_line()]
    if bad:
        raise ValueError(f"gprMax runs 2D models: targets must cross the line (axis along y); not {bad}")
    dx = scene.dx
    ys = scene.depth_m
    local = width is not None
    width = scene.width_m if width is None else width
    air = scene.air_m if air is None else air
    s = g.Scene()
    s.add(g.Title(name=scene.name))
    s.add(g.DomainMode(mode="TM"))
    s.add(g.Domain(p1=(width, scene.depth_m + air, INF)))
    s.add(g.Discretisation(p1=(dx, dx, dx)))
    s.add(g.TimeWindow(time=scene.time_window))
    s.add(g.OMPThreads(n=1))
    m = scene.medium
    # "host" always exists: the body of a homogeneous host, and the bumps of a rough surface
    s.add(g.Material(er=m.eps_r, se=m.conductivity_s_m, mr=1, sm=0, id="host"))
    if m.peplinski:
        if local:
            raise ValueError("heterogeneous (Peplinski) soil needs one domain for all traces: use run_gprmax")
        p = m.peplinski
        s.add(g.SoilPeplinski(sand_fraction=p["sand"], clay_fraction=p["clay"], bulk_density=p["bulk_density"],
                              sand_density=p["sand_density"], water_fraction_lower=p["water"][0],
                              water_fraction_upper=p["water"][1], id="soil_mix"))
        s.add(g.FractalBox(p1=(0, 0, 0), p2=(scene.width_m, ys, INF), frac_dim=p.get("fractal_dim", 1.5),
                           weighting=(1, 1, 1), n_materials=p.get("n_materials", 20), mixing_model_id="soil_mix",
                           id="host_box", seed=scene.seed))
    else:
        s.add(g.Box(p1=(0, 0, 0), p2=(width, ys, INF), material_id="host"))
    tops = [lay.top_m for lay in scene.layers]
    if tops and (min(tops) <= 0 or max(tops) >= ys or any(b <= a for a, b in zip(tops, tops[1:]))):
        raise ValueError(f"layer tops must increase inside (0, {ys}) m below the surface, got {tops}")
    for k, lay in enumerate(scene.layers):  # each from its top down to the floor; deeper ones overwrite
        s.add(g.Material(er=lay.eps_r, se=lay.conductivity_s_m, mr=1, sm=0, id=f"layer{k}"))
        s.add(g.Box(p1=(0, 0, 0), p2=(width, ys - lay.top_m, INF), material_id=f"layer{k}"))

    def inside(cx, depth, r):  # does a circle (world x, depth of its top) reach into the model more than a sliver?
        if ys - depth <= 2 * dx:  # its top (height ys - depth above the floor) within two cells of the floor
            return False
        if not local:
            return True
        return cx + r > x0 + 2 * dx and cx - r < x0 + width - 2 * dx

    targets = [t for t in scene.targets if inside(t.x_m, t.depth_m, t.radius_m)]
    stones = [(k, st) for k, st in enumerate(scene.stones) if inside(st.x_m, st.depth_m, st.radius_m)]
    used = {t.material for t in targets} | {t.fill for t in targets if t.fill}
    for name in sorted(used - {"pec"}):
        er, se = MATERIALS[name]
        s.add(g.Material(er=er, se=se, mr=1, sm=0, id=_mat_id(name)))
    if scene.rough_surface_m > 0:
        rng = np.random.default_rng(scene.seed + 1)
        col = max(dx, 0.01)
        n = int(math.ceil(scene.width_m / col))
        h = scene.rough_surface_m * rng.standard_normal(n)
        for i, hi in enumerate(h):
            xa, xb = max(i * col, x0) - x0, min((i + 1) * col, scene.width_m, x0 + width) - x0
            if xb - xa < dx:  # a sliver at the edge (or outside the model): nothing to build
                continue
            if hi >= dx:
                s.add(g.Box(p1=(xa, ys, 0), p2=(xb, ys + hi, INF), material_id="host"))
            elif hi <= -dx:
                s.add(g.Box(p1=(xa, ys + hi, 0), p2=(xb, ys, INF), material_id="free_space"))
    for k, st in stones:
        s.add(g.Material(er=st.eps_r, se=0.0, mr=1, sm=0, id=f"stone{k}"))
        cy = ys - st.depth_m - st.radius_m
        s.add(g.Cylinder(p1=(st.x_m - x0, cy, 0), p2=(st.x_m - x0, cy, INF), r=st.radius_m,
                         material_id=f"stone{k}"))
    for t in targets:
        cy = ys - t.depth_m - t.radius_m
        s.add(g.Cylinder(p1=(t.x_m - x0, cy, 0), p2=(t.x_m - x0, cy, INF), r=t.radius_m,
                         material_id=_mat_id(t.material)))
        if t.fill:
            s.add(g.Cylinder(p1=(t.x_m - x0, cy, 0), p2=(t.x_m - x0, cy, INF), r=t.radius_m - t.wall_m,
                             material_id=_mat_id(t.fill)))
    f = scene.antenna.frequency_hz
    s.add(g.Waveform(wave_type="ricker", amp=1, freq=f, id="pulse"))
    if local:
        s.add(g.HertzianDipole(p1=(tx_x - x0, ys, 0), polarisation="z", waveform_id="pulse"))
        s.add(g.Rx(p1=(rx_x - x0, ys, 0), outputs=["Ez"]))
        return s
    half = scene.antenna.offset_m / 2
    xs = scene.x_start_m
    s.add(g.HertzianDipole(p1=(xs - half, ys, 0), polarisation="z", waveform_id="pulse"))
    s.add(g.Rx(p1=(xs + half, ys, 0), outputs=["Ez"]))
    if scene.n_traces > 1:  # gprMax moves model i by (i - 1) steps
        s.add(g.SrcSteps(p1=(scene.trace_step_m, 0, 0)))
        s.add(g.RxSteps(p1=(scene.trace_step_m, 0, 0)))
    return s


def _snapped(scene: Scene) -> Scene:
    """A copy of ``scene`` with the trace step, start and tx-rx offset on whole cells."""
    scene = copy.deepcopy(scene)
    dx = scene.dx
    scene.trace_step_m = max(round(scene.trace_step_m / dx), 1) * dx
    scene.x_start_m = round(scene.x_start_m / dx) * dx
    scene.antenna.offset_m = 2 * max(round(scene.antenna.offset_m / 2 / dx), 1) * dx
    return scene


def following_domain(scene: Scene) -> dict:
    """Size of the antenna-following model of ``scene`` (see :func:`run_gprmax_following`).

    Every point whose echo can arrive within the time window lies within
    ``reach = v * window / 2`` of the antenna midpoint; the model spans that reach on
    each side, plus half the tx-rx offset, gprMax's PML (10 cells) and two cells.
    Returns ``half_width_m, air_m, nx, ny, iterations`` and ``cell_steps`` (the FDTD work
    of one trace: cells x iterations).
    """
    dx = scene.dx
    window = scene.time_window
    # the fastest host layer sets how far an echo can come from within the window
    reach = C0 / math.sqrt(min(eps for _, eps in scene.eps_profile())) * window / 2
    half = reach + scene.antenna.offset_m / 2 + (PML_CELLS + 2) * dx
    half = math.ceil(half / dx) * dx
    lam = C0 / (scene.antenna.frequency_hz * math.sqrt(scene.medium.eps_r))
    air = max(scene.air_m, 0.5 * lam, (PML_CELLS + 15) * dx)
    air = math.ceil(air / dx) * dx
    nx = int(round(2 * half / dx))
    ny = int(math.ceil((scene.depth_m + air) / dx - 1e-9))
    iterations = int(math.ceil(window / (dx / (C0 * math.sqrt(2)))))  # 2D Courant limit
    return {"half_width_m": half, "air_m": air, "nx": nx, "ny": ny, "iterations": iterations,
            "cell_steps": float(nx) * ny * iterations}


def following_cost(scene: Scene) -> float:
    """FDTD work of :func:`run_gprmax_following` for ``scene``: cells x iterations x traces."""
    return following_domain(scene)["cell_steps"] * scene.n_traces


def run_gprmax_following(scene: Scene, workdir, *, x=None, progress=None):
    """Simulate ``scene`` with gprMax, one small model per trace that follows the antenna.

    A B-scan of hundreds of traces over a long line would need a model as long as the
    line for every trace. Here trace ``i`` runs in a model centred on its own antenna
    midpoint, just wide enough that everything outside it answers after the time
    window closes (:func:`following_domain`); the host fills the whole model and
    targets are clipped to it. The model's origin is a whole number of cells from the
    world origin, so targets sit on the same cells for every trace as in one long model.

    ``x``: antenna midpoints (m, default the scene's even steps; snapped to the grid).
    ``workdir`` keeps one ``trace_{i:05d}.npy`` per finished trace, written atomically:
    a killed run resumes where it stopped. Returns ``(Survey, info)`` as :func:`run_gprmax`
    (positions are the snapped midpoints; the scene is stored as simulated).
    """
    g = require("gprMax")
    from gpr3d.core.poses import quat_from_yaw
    from gpr3d.core.survey import Survey
    from gpr3d.io.gprmax import read_gprmax

    scene = _snapped(scene)
    dx = scene.dx
    x = scene.trace_midpoints_x() if x is None else np.asarray(x, dtype=float)
    if x.ndim != 1 or x.size < 1 or not np.all(np.isfinite(x)):
        raise ValueError("x must be a non-empty 1-D array of finite antenna midpoints (m)")
    x = np.round(x / dx) * dx
    dom = following_domain(scene)
    half, air = dom["half_width_m"], dom["air_m"]
    off2 = scene.antenna.offset_m / 2
    work = Path(workdir)
    work.mkdir(parents=True, exist_ok=True)
    water = any(t.fill == "water" for t in scene.targets)
    logging.getLogger("gprMax").setLevel(logging.ERROR)
    quiet = io.StringIO()
    t0 = time.perf_counter()
    dt = None
    traces = []
    for i, xm in enumerate(x):
        npy = work / f"trace_{i:05d}.npy"
        if not npy.exists():
            origin = round((xm - half) / dx) * dx
            gs = build_gprmax_scene(scene, x0=origin, width=2 * half, air=air, tx_x=xm - off2, rx_x=xm + off2)
            out = work / f"model_{i:05d}.h5"
            with contextlib.redirect_stdout(quiet):
                g.run(scenes=[gs], n=1, outputfile=str(out), hide_progress_bars=True, log_level=40,
                      allow_underresolved=water)
            sv = read_gprmax(out)[0]
            tmp = work / f"trace_{i:05d}.tmp.npy"
            np.save(tmp, np.stack([np.full(sv.n_samples, sv.dt_s), sv.data[0]]))
            tmp.replace(npy)  # the trace appears whole, or not at all
            out.unlink(missing_ok=True)
            quiet.seek(0)
            quiet.truncate()
        rec = np.load(npy)
        if dt is None:
            dt = float(rec[0, 0])
        elif abs(rec[0, 0] - dt) > 1e-6 * dt or rec.shape[1] != traces[0].size:
            raise RuntimeError(f"{npy}: another grid than the other traces; delete {work} and run again")
        traces.append(rec[1])
        if progress:
            progress(i + 1, x.size)
    wall = time.perf_counter() - t0
    data = np.stack(traces).astype(np.float32)
    pos = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    scene.n_traces = int(x.size)
    info = {"engine": "gprmax", "runner": "following", "gprmax_version": g.__version__, "dx_m": dx,
            "time_window_s": scene.time_window, "iterations": int(data.shape[1]), "dt_s": dt, "wall_s": wall,
            "allow_underresolved": water, "model": {k: dom[k] for k in ("half_width_m", "air_m", "nx", "ny")}}
    survey = Survey(data=data, dt_s=dt, positions_xyz=pos, offset_m=scene.antenna.offset_m,
                    frequency_hz=scene.antenna.frequency_hz, eps_r=scene.medium.eps_r,
                    orientations_quat_wxyz=quat_from_yaw(np.zeros(x.size)),
                    metadata={"format": "gprmax", "component": "Ez", "scene": scene.to_dict(), "simulation": info})
    return survey, info


def run_gprmax(scene: Scene, *, workdir=None, keep_files: bool = False):
    """Simulate ``scene`` with gprMax; return ``(Survey, info)``.

    The Survey is the merged B-scan (``Ez``), with positions in the world frame
    (surface at z = 0) and ``metadata["scene"]`` the scene as simulated. ``info``
    records the gprMax version, grid, iterations and wall time. gprMax moves sources
    by whole cells, so a copy of ``scene`` with the trace step, start and offset
    snapped to the grid is run; ``scene`` itself is left as it was.
    """
    g = require("gprMax")
    merge = require("gprMax.toolboxes.Utilities.outputfiles_merge")
    from gpr3d.io.gprmax import read_gprmax

    scene = _snapped(scene)
    dx = scene.dx
    tmp = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="gpr3d_gprmax_"))
    tmp.mkdir(parents=True, exist_ok=True)
    base = tmp / "bscan"
    t0 = time.perf_counter()
    gscene = build_gprmax_scene(scene)
    water = any(t.fill == "water" for t in scene.targets)
    quiet = io.StringIO()
    logging.getLogger("gprMax").setLevel(logging.ERROR)
    try:
        with contextlib.redirect_stdout(quiet):
            g.run(scenes=[gscene] * scene.n_traces, n=scene.n_traces, outputfile=str(base) + ".h5",
                  hide_progress_bars=True, log_level=40, allow_underresolved=water)
        outs = [tmp / f"bscan{i}.h5" for i in range(1, scene.n_traces + 1)]
        merged = tmp / "bscan_merged.h5"
        with contextlib.redirect_stdout(quiet):
            merge.merge_files(outs, merged)
        survey = read_gprmax(merged)[0]
    finally:
        if not keep_files and not workdir:
            shutil.rmtree(tmp, ignore_errors=True)
    wall = time.perf_counter() - t0
    # world frame: gprMax y (up) became world z; put the surface at z = 0, y across at 0
    pos = survey.positions_xyz.copy()
    pos[:, 2] -= scene.depth_m
    pos[:, 1] = 0.0
    info = {"engine": "gprmax", "gprmax_version": g.__version__, "dx_m": dx, "time_window_s": scene.time_window,
            "iterations": survey.n_samples, "dt_s": survey.dt_s, "wall_s": wall,
            "allow_underresolved": water}
    meta = dict(survey.metadata)
    meta.update({"scene": scene.to_dict(), "simulation": info})
    survey = survey.replace(positions_xyz=pos, eps_r=scene.medium.eps_r, frequency_hz=scene.antenna.frequency_hz,
                            metadata=meta)
    return survey, info
