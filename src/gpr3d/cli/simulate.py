"""``gpr3d simulate``: build a labelled dataset of simulated B-scans (resumable)."""

from __future__ import annotations

from gpr3d.cli._common import _writable

NAME = "simulate"
HELP = "build a labelled dataset of simulated B-scans (resumable)"
EPILOG = ("examples:\n  gpr3d simulate --engine gprmax --n 1 --seed 0 --out sim1\n"
             "  gpr3d simulate --n 400 --workers 2 --out gprmax400         (re-run to resume)\n"
             "  gpr3d simulate --n 5000 --scheduler tcp://10.0.0.5:8786 --out big\n"
             "  gpr3d simulate --preset survey --seed 4242 --n 180 --workers 1 --out gprmax_survey   "
             "(held-out set)")


def add_arguments(sp):
    sp.add_argument("--out", required=True, help="dataset folder (re-running with the same settings resumes)")
    sp.add_argument("--n", type=int, required=True, help="number of samples (scene indices 0..n-1)")
    sp.add_argument("--seed", type=int, default=0, help="master seed: scene i is sample_scene(seed, i)")
    sp.add_argument("--engine", choices=("gprmax", "forward"), default="gprmax", help="simulator (default gprmax)")
    sp.add_argument("--workers", type=int, default=2, help="local Dask worker processes (default 2)")
    sp.add_argument("--scheduler", default=None, help="tcp://HOST:PORT of a Dask scheduler to run on instead")
    sp.add_argument("--preset", choices=("standard", "tiny", "survey"), default="standard",
                    help="scene sizes: standard (the sampler's ranges), tiny (seconds each, for smoke tests) or "
                         "survey (survey-scale scans of the held-out gprMax set, 100-200 traces each)")
    sp.add_argument("--host", choices=("concrete", "soil"), default=None, help="only this host medium")
    sp.add_argument("--image-height", type=int, default=256, help="rows of the detector images (default 256)")
    sp.add_argument("--start", type=int, default=0,
                    help="first scene index (build start..n-1; e.g. to share one set between machines)")
    sp.add_argument("--max-seconds", type=float, default=None,
                    help="stop after this long, keeping every finished sample (re-run to resume)")
    sp.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args):
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset

    _writable(args.out, "--out")
    cfg = SimulateConfig(out=args.out, n=args.n, seed=args.seed, engine=args.engine, workers=args.workers,
                         scheduler=args.scheduler, image_height=args.image_height, preset=args.preset,
                         host=args.host, start=args.start, max_seconds=args.max_seconds)
    summary = build_dataset(cfg, progress=not args.no_progress)
    if summary["samples_per_s"]:
        print(f"throughput: {summary['samples_per_s'] * 3600:.0f} samples/hour "
              f"({summary['mean_sample_wall_s']:.1f} s per sample per worker)")
    return 0
