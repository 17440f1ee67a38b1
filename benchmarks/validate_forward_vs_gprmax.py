"""Forward model against gprMax on the same 2D scenes: travel times and amplitudes.

Validation scenes come from the dataset sampler (``sample_scene(seed, i)``: concrete
and soil, 0.4-2.6 GHz, eps_r 3-20), each keeping one target (so echoes do not
interfere) placed mid-scene, with no clutter. gprMax runs them on a grid twice as
fine as the training data's (20 cells per wavelength at twice the peak frequency,
so its own dispersion stays below the tolerance we test), at five antenna
positions: above the target, and where the ray leaves 20 and 35 degrees from the
vertical on both sides. A run without the target is subtracted (it holds the
direct waves). The forward model simulates the same positions on the same time
grid with 2D spreading and the half-derivative Ricker (a 2D line source's far
field). Both are picked alike: the Hilbert-envelope peak within half a period
of the analytic time. Reported: apex two-way time differences (ns), limb
two-way time differences (%), and amplitude ratios after one global scale.

The gprMax runs are cached in --work (re-running reuses them).

    python benchmarks/validate_forward_vs_gprmax.py [--n 24] [--work validation_runs]
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import math
import time
from pathlib import Path

import numpy as np
from scipy.signal import hilbert

from gpr3d.processing.picking import pick_peak
from gpr3d.simulation.forward import forward_model, scene_to_forward
from gpr3d.simulation.gprmax_runner import build_gprmax_scene
from gpr3d.simulation.labels import hyperbola_times
from gpr3d.simulation.sampler import sample_scene

ANGLES_DEG = (0.0, -20.0, 20.0, -35.0, 35.0)


def validation_scene(seed: int, index: int):
    s = sample_scene(seed, index)
    t = s.targets[0]
    s.targets = [t]
    s.stones, s.rough_surface_m = [], 0.0
    s.dx_m = s.default_dx() / 2
    dx = s.dx_m
    t.x_m = round(s.width_m / 2 / dx) * dx
    s.antenna.offset_m = 2 * max(round(s.antenna.offset_m / 2 / dx), 1) * dx
    s.name = f"validation_{seed}_{index}"
    return s


def positions(scene):
    t = scene.targets[0]
    d = t.depth_m + t.radius_m
    dx = scene.dx
    xs = [t.x_m + d * math.tan(math.radians(a)) for a in ANGLES_DEG]
    return [round(x / dx) * dx for x in xs]


def run_gprmax_positions(scene, xs, out: Path):
    """gprMax A-scans (Ez) at midpoints ``xs`` minus a run without targets: ``(len(xs), n), dt``."""
    import gprMax
    import h5py

    if out.exists():
        with h5py.File(out) as f:
            return f["traces"][()], float(f.attrs["dt"]), float(f.attrs["wall_s"])
    t0 = time.perf_counter()
    scenes = []
    empty = copy.deepcopy(scene)
    empty.targets = []
    for sc, x in [(empty, xs[0])] + [(scene, x) for x in xs]:
        c = copy.deepcopy(sc)
        c.n_traces, c.x_start_m = 1, x
        scenes.append(build_gprmax_scene(c))
    base = out.parent / (out.stem + "_run")
    with contextlib.redirect_stdout(io.StringIO()):
        gprMax.run(scenes=scenes, n=len(scenes), outputfile=str(base) + ".h5", hide_progress_bars=True,
                   log_level=40, allow_underresolved=True)
    traces = []
    for i in range(1, len(scenes) + 1):
        p = Path(f"{base}{i}.h5")
        with h5py.File(p) as f:
            traces.append(f["rxs/rx1/Ez"][()])
            dt = float(f.attrs["dt"])
        p.unlink()
    traces = np.asarray(traces)
    traces = traces[1:] - traces[0]
    wall = time.perf_counter() - t0
    with h5py.File(out, "w") as f:
        f["traces"] = traces
        f.attrs["dt"] = dt
        f.attrs["wall_s"] = wall
        f.attrs["scene"] = scene.to_json()
    return traces, dt, wall


def compare(scene, g, dt):
    xs = np.asarray(positions(scene))
    f = scene.antenna.frequency_hz
    delay = math.sqrt(2) / f
    s1 = copy.deepcopy(scene)
    s1.n_traces, s1.x_start_m, s1.trace_step_m = len(xs), 0.0, 1.0
    fwd = forward_model(scene_to_forward(scene), np.stack([xs, 0 * xs, 0 * xs], axis=1),
                        offset_m=scene.antenna.offset_m, frequency_hz=f, n_samples=g.shape[1], dt_s=dt,
                        wavelet="ricker_half", spreading="2d")
    eg, ef = np.abs(hilbert(g, axis=1)), np.abs(hilbert(fwd, axis=1))
    # analytic two-way times at these midpoints
    s1.trace_step_m, s1.x_start_m = 1e-9, 0.0
    twt = []
    for x in xs:
        s1.x_start_m = x
        s1.n_traces = 1
        twt.append(hyperbola_times(s1, scene.targets[0])[0])
    rows = []
    for k, a in enumerate(ANGLES_DEG):
        tg, ag = pick_peak(eg, dt, k, delay + twt[k], 0.5 / f)
        tf, af = pick_peak(ef, dt, k, delay + twt[k], 0.5 / f)
        rows.append({"angle": a, "twt_true": twt[k], "twt_gprmax": tg - delay, "twt_fwd": tf - delay,
                     "amp_gprmax": ag, "amp_fwd": af})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=24, help="number of validation scenes")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--work", type=Path, default=Path("validation_runs"))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    args.work.mkdir(parents=True, exist_ok=True)
    results, wall = [], 0.0
    for i in range(args.n):
        sc = validation_scene(args.seed, i)
        g, dt, w = run_gprmax_positions(sc, positions(sc), args.work / f"{sc.name}.h5")
        wall += w
        t = sc.targets[0]
        for r in compare(sc, g, dt):
            r.update({"scene": sc.name, "kind": t.kind, "eps_r": sc.medium.eps_r, "f": sc.antenna.frequency_hz,
                      "depth_m": t.depth_m, "radius_m": t.radius_m})
            results.append(r)
    apex = [r for r in results if r["angle"] == 0.0]
    limb = [r for r in results if r["angle"] != 0.0]
    d_apex = np.abs([r["twt_fwd"] - r["twt_gprmax"] for r in apex]) * 1e9
    d_apex_true = np.abs([r["twt_gprmax"] - r["twt_true"] for r in apex]) * 1e9
    d_limb = np.abs([r["twt_fwd"] / r["twt_gprmax"] - 1 for r in limb]) * 100
    ratio = np.array([r["amp_fwd"] / r["amp_gprmax"] for r in results])
    scale = np.median(ratio)
    amp_rel = np.abs(ratio / scale - 1) * 100
    # angular fall-off: limb/apex amplitude within each scene, forward vs gprMax
    by = {}
    for r in results:
        by.setdefault(r["scene"], {})[r["angle"]] = r
    fall = np.array([(s[a]["amp_fwd"] / s[0.0]["amp_fwd"]) / (s[a]["amp_gprmax"] / s[0.0]["amp_gprmax"])
                     for s in by.values() for a in ANGLES_DEG if a != 0.0])
    print(f"forward model vs gprMax (fine grid): {args.n} scenes, {len(apex)} apexes, {len(limb)} limb picks; "
          f"gprMax time {wall:.0f} s")
    print(f"{'quantity':<48} {'median':>8} {'p95':>8} {'max':>8} {'within':>8}")
    print(f"{'apex two-way time |fwd - gprMax| (ns)':<48} {np.median(d_apex):8.3f} "
          f"{np.percentile(d_apex, 95):8.3f} {d_apex.max():8.3f} {np.mean(d_apex <= 0.05) * 100:7.0f}%  (0.05 ns)")
    print(f"{'limb two-way time |fwd / gprMax - 1| (%)':<48} {np.median(d_limb):8.2f} "
          f"{np.percentile(d_limb, 95):8.2f} {d_limb.max():8.2f} {np.mean(d_limb <= 2.0) * 100:7.0f}%  (2 %)")
    print(f"{'gprMax apex vs analytic time |dt| (ns)':<48} {np.median(d_apex_true):8.3f} "
          f"{np.percentile(d_apex_true, 95):8.3f} {d_apex_true.max():8.3f}")
    print(f"{'amplitude fwd/gprMax after one scale |rel| (%)':<48} {np.median(amp_rel):8.1f} "
          f"{np.percentile(amp_rel, 95):8.1f} {amp_rel.max():8.1f}")
    print(f"{'limb/apex amplitude, fwd over gprMax |rel| (%)':<48} {np.median(np.abs(fall - 1)) * 100:8.1f} "
          f"{np.percentile(np.abs(fall - 1), 95) * 100:8.1f} {np.abs(fall - 1).max() * 100:8.1f}")
    kinds = sorted({r["kind"] for r in apex})
    print("apex |fwd - gprMax| median by kind (ns): " + ", ".join(
        f"{k} {np.median([abs(r['twt_fwd'] - r['twt_gprmax']) * 1e9 for r in apex if r['kind'] == k]):.3f}"
        f" (n={sum(r['kind'] == k for r in apex)})" for k in kinds))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=float))


if __name__ == "__main__":
    main()
