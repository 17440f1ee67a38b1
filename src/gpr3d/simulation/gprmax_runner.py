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
from gpr3d.simulation.scene import MATERIALS, Scene

__all__ = ["build_gprmax_scene", "run_gprmax"]

INF = float("inf")


def _mat_id(name: str) -> str:
    return "pec" if name == "pec" else f"m_{name}"


def build_gprmax_scene(scene: Scene):
    """A ``gprMax.Scene`` for the first trace (with source/receiver steps for the rest)."""
    g = require("gprMax")
    bad = [t.kind for t in scene.targets if not t.crosses_line()]
    if bad:
        raise ValueError(f"gprMax runs 2D models: targets must cross the line (axis along y); not {bad}")
    dx = scene.dx
    ys = scene.depth_m
    s = g.Scene()
    s.add(g.Title(name=scene.name))
    s.add(g.DomainMode(mode="TM"))
    s.add(g.Domain(p1=(scene.width_m, scene.depth_m + scene.air_m, INF)))
    s.add(g.Discretisation(p1=(dx, dx, dx)))
    s.add(g.TimeWindow(time=scene.time_window))
    s.add(g.OMPThreads(n=1))
    m = scene.medium
    # "host" always exists: the body of a homogeneous host, and the bumps of a rough surface
    s.add(g.Material(er=m.eps_r, se=m.conductivity_s_m, mr=1, sm=0, id="host"))
    if m.peplinski:
        p = m.peplinski
        s.add(g.SoilPeplinski(sand_fraction=p["sand"], clay_fraction=p["clay"], bulk_density=p["bulk_density"],
                              sand_density=p["sand_density"], water_fraction_lower=p["water"][0],
                              water_fraction_upper=p["water"][1], id="soil_mix"))
        s.add(g.FractalBox(p1=(0, 0, 0), p2=(scene.width_m, ys, INF), frac_dim=p.get("fractal_dim", 1.5),
                           weighting=(1, 1, 1), n_materials=p.get("n_materials", 20), mixing_model_id="soil_mix",
                           id="host_box", seed=scene.seed))
    else:
        s.add(g.Box(p1=(0, 0, 0), p2=(scene.width_m, ys, INF), material_id="host"))
    used = {t.material for t in scene.targets} | {t.fill for t in scene.targets if t.fill}
    for name in sorted(used - {"pec"}):
        er, se = MATERIALS[name]
        s.add(g.Material(er=er, se=se, mr=1, sm=0, id=_mat_id(name)))
    if scene.rough_surface_m > 0:
        rng = np.random.default_rng(scene.seed + 1)
        col = max(dx, 0.01)
        n = int(math.ceil(scene.width_m / col))
        h = scene.rough_surface_m * rng.standard_normal(n)
        for i, hi in enumerate(h):
            x0, x1 = i * col, min((i + 1) * col, scene.width_m)
            if x1 - x0 < dx:  # a sliver at the edge: nothing to build
                continue
            if hi >= dx:
                s.add(g.Box(p1=(x0, ys, 0), p2=(x1, ys + hi, INF), material_id="host"))
            elif hi <= -dx:
                s.add(g.Box(p1=(x0, ys + hi, 0), p2=(x1, ys, INF), material_id="free_space"))
    for k, st in enumerate(scene.stones):
        s.add(g.Material(er=st.eps_r, se=0.0, mr=1, sm=0, id=f"stone{k}"))
        cy = ys - st.depth_m - st.radius_m
        s.add(g.Cylinder(p1=(st.x_m, cy, 0), p2=(st.x_m, cy, INF), r=st.radius_m, material_id=f"stone{k}"))
    for t in scene.targets:
        cy = ys - t.depth_m - t.radius_m
        s.add(g.Cylinder(p1=(t.x_m, cy, 0), p2=(t.x_m, cy, INF), r=t.radius_m, material_id=_mat_id(t.material)))
        if t.fill:
            s.add(g.Cylinder(p1=(t.x_m, cy, 0), p2=(t.x_m, cy, INF), r=t.radius_m - t.wall_m,
                             material_id=_mat_id(t.fill)))
    f = scene.antenna.frequency_hz
    s.add(g.Waveform(wave_type="ricker", amp=1, freq=f, id="pulse"))
    half = scene.antenna.offset_m / 2
    x0 = scene.x_start_m
    s.add(g.HertzianDipole(p1=(x0 - half, ys, 0), polarisation="z", waveform_id="pulse"))
    s.add(g.Rx(p1=(x0 + half, ys, 0), outputs=["Ez"]))
    if scene.n_traces > 1:  # gprMax moves model i by (i - 1) steps
        s.add(g.SrcSteps(p1=(scene.trace_step_m, 0, 0)))
        s.add(g.RxSteps(p1=(scene.trace_step_m, 0, 0)))
    return s


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

    scene = copy.deepcopy(scene)
    dx = scene.dx
    # gprMax moves sources by whole cells: snap the step and the start to the grid
    scene.trace_step_m = max(round(scene.trace_step_m / dx), 1) * dx
    scene.x_start_m = round(scene.x_start_m / dx) * dx
    scene.antenna.offset_m = 2 * max(round(scene.antenna.offset_m / 2 / dx), 1) * dx
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
