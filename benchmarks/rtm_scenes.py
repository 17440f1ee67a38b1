"""gprMax B-scans over layered hosts with close targets, for the migration comparison (``eval_rtm.py``).

Three 2D scenes, each simulated trace by trace by gprMax 4 (``run_gprmax_following``), resumable (a killed run
continues from its finished traces), written to ``--out/<name>.h5`` (a gpr3d survey with the scene in its
metadata). About 2-6 minutes a scene on one core.

    python benchmarks/rtm_scenes.py [--out build/rtm_scenes]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from gpr3d.simulation.scene import Antenna, Layer, Medium, Scene, Target


def scenes() -> list[Scene]:
    """Soil over a wetter subsoil with two pipes 25 cm apart; a concrete slab on its base with a rebar mat at 12 cm
    spacing; an asphalt layer over a base course with bars 10 cm apart at two depths."""
    soil = Scene(medium=Medium("soil", 6.0, 0.003), layers=[Layer(0.35, 12.0, 0.006)],
                 targets=[Target("steel_pipe", 0.8, 0.55, 0.04), Target("steel_pipe", 1.05, 0.55, 0.04),
                          Target("pvc_pipe", 1.7, 0.25, 0.05, material="pvc", fill="air", wall_m=0.008),
                          Target("steel_pipe", 2.1, 0.8, 0.05)],
                 antenna=Antenna(500e6, 0.1), width_m=2.6, depth_m=1.1, n_traces=121, trace_step_m=0.02,
                 x_start_m=0.1, name="layered_soil")
    slab = Scene(medium=Medium("concrete", 7.0, 0.004), layers=[Layer(0.16, 12.0, 0.01)],
                 targets=[Target("rebar", x, 0.05, 0.008) for x in (0.2, 0.32, 0.44, 0.56)]
                 + [Target("rebar", 0.8, 0.11, 0.01), Target("steel_pipe", 0.62, 0.24, 0.02)],
                 antenna=Antenna(1.6e9, 0.04), width_m=1.0, depth_m=0.36, n_traces=111, trace_step_m=0.008,
                 x_start_m=0.06, name="layered_slab")
    road = Scene(medium=Medium("concrete", 5.0, 0.002), layers=[Layer(0.1, 9.0, 0.004), Layer(0.3, 15.0, 0.01)],
                 targets=[Target("rebar", 0.35, 0.14, 0.01), Target("rebar", 0.45, 0.14, 0.01),
                          Target("rebar", 0.9, 0.22, 0.012), Target("rebar", 1.0, 0.22, 0.012),
                          Target("steel_pipe", 0.65, 0.38, 0.03)],
                 antenna=Antenna(1.0e9, 0.06), width_m=1.3, depth_m=0.55, n_traces=111, trace_step_m=0.011,
                 x_start_m=0.04, name="layered_road")
    return [soil, slab, road]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="build/rtm_scenes")
    args = ap.parse_args(argv)
    from gpr3d.simulation.gprmax_runner import run_gprmax_following

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for sc in scenes():
        dest = out / f"{sc.name}.h5"
        if dest.exists():
            print(f"{dest}: done")
            continue
        t = time.perf_counter()
        survey, info = run_gprmax_following(sc, out / sc.name)
        survey.save(dest)
        print(f"{dest}: {survey.n_traces} traces x {survey.n_samples} samples in {time.perf_counter() - t:.0f} s",
              flush=True)


if __name__ == "__main__":
    main()
