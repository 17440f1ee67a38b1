"""Table 1 on real data (issue 29, item 7): every detector of the comparison trained with one CPU budget.

    python benchmarks/table1_real.py --runs runs/table1 [--budget 600] [--jobs 1] [--splits std air iecas]
        [--models frcnn_lean ssdlite ...] [--gprmax 40] [--pgpr DIR] [--out benchmarks/results]

Every model of ``gpr3d.detection.models.MODELS`` starts from nothing (``weights=None``; no pretrained backbone can
be downloaded here) and trains on one CPU thread, alone on the machine (``--jobs 1``: units side by side share
caches and memory bandwidth, and a step's time then depends on its neighbour), for the same budget of step
seconds: a throw-away probe of ``PROBE_STEPS`` steps times one step of 4 windows (``probe_seconds``), and the
run gets ``budget / seconds per step`` steps (at least ``MIN_STEPS``), with its whole warm-up and cosine schedule
inside them, so no model is cut off mid-schedule.
The windows are the shipped fine-tuning's mix (``references/detection/finetune_pgpr.py``): 75 % from P-GPR's
train pictures (steel -> rebar, pipe -> pvc_pipe; 256 rows = 8 ns), the rest survey-scale synthetic records;
the device-held-out splits add that recipe's best measured settings for a radar never seen (half the synthetic
records wall scans, every window stretched along its traces 0.35-2.5x with gain and noise changed,
``benchmarks/results/pgpr_heldout.md``).

Splits (``--splits``):
  std    P-GPR train (both radars) -> P-GPR val (56 pictures), and the held-out gprMax survey set
         (``datasets/gprmax_survey.h5``, its first ``--gprmax`` records; nothing trains on it)
  air    P-GPR train ``AIR_*`` -> every ``IECAS_*`` picture of train and val (device held out)
  iecas  P-GPR train ``IECAS_*`` -> every ``AIR_*`` picture of train and val

A unit is one model on one split: probe, train, save ``weights.pt``, evaluate (``gpr3d.detection.evaluate``:
pycocotools, class-averaged over rebar and pvc_pipe and class-agnostic; on gprMax also apex recall). Units run
``--jobs`` at a time, each its own process with one thread; every step resumes (training checkpoints, each unit's
figures in ``RUNS/SPLIT/MODEL/unit.json``): after a kill, run the same line again. The table
(``table1_real.md`` in ``--out``) is rewritten after every unit; units not yet done are marked pending. Reference
rows: the shipped default (synthetic pretraining on a GPU, then fine-tuned on P-GPR train on the CPU; with and
without its box refiner), and the P-GPR paper's published figures on its test split (pretrained backbones).

P-GPR: Yue, Qin, Zhu, Ye, Wang, "P-GPR: a Ground Penetrating Radar Dataset for Pipeline Detection", CIKM '26;
CC BY 4.0. Weights trained here carry that credit in their provenance.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402
from eval_pgpr import PGPR, PGPR_DEFAULT, PUBLISHED, pgpr_records  # noqa: E402

PROBE_STEPS = 24  #: steps of the throw-away run that times a step (probe_seconds)
PROBE_SKIP = 4  #: its first steps, not counted
MIN_STEPS = 20
BATCH = 4
REAL_SHARE = 0.75
SPLITS = {  # name: (train pictures' glob, test split, test pictures' glob, held-out recipe)
    "std": (None, "val", None, False),
    "air": ("AIR_*", "train,val", "IECAS_*", True),
    "iecas": ("IECAS_*", "train,val", "AIR_*", True),
}
SPLIT_TITLE = {"std": "P-GPR train -> P-GPR val (standard split)",
               "air": "device held out: AIR train -> IECAS train + val",
               "iecas": "device held out: IECAS train -> AIR train + val"}
SHIPPED = "shipped default"  #: the reference unit's model name (std split only)
#: The device-held-out splits' reference rows, measured by ``benchmarks/results/pgpr_heldout.md`` (AMD znver5, one
#: thread): the shipped recipe's stage-3 detector (synthetic pretraining on a GPU), then 1,000 CPU steps on the one
#: radar (`--wall 0.5 --augment --stretch 0.35 2.5`: the units here draw the same wall share and stretch, without
#: --augment's gain and noise). Class-averaged mAP@0.5, mAP@0.75, mAP@[.5:.95],
#: AR@100, recall@0.5; class-agnostic mAP@0.5, recall@0.5.
HELD_OUT_REFERENCE = {"air": (0.410, 0.045, 0.139, 0.271, 0.693, 0.553, 0.818),
                      "iecas": (0.178, 0.002, 0.035, 0.182, 0.613, 0.282, 0.761)}
METRICS = ("mAP@0.5", "mAP@0.75", "mAP", "AR@10", "AR@100", "recall@0.5")


def planned_steps(budget_s: float, s_per_step: float) -> int:
    """Steps that fit ``budget_s`` seconds at ``s_per_step`` (never fewer than ``MIN_STEPS``)."""
    return max(MIN_STEPS, int(budget_s // s_per_step))


def _walls(losses_csv) -> list[float]:
    """The ``wall_s`` column of a training run's ``losses.csv`` (seconds since its sitting began, a row a step)."""
    import csv

    with open(losses_csv, newline="") as f:
        return [float(r["wall_s"]) for r in csv.DictReader(f)]


def step_seconds(losses_csv) -> float:
    """Seconds of training the kept steps of a (resumed) run took, from its ``losses.csv``.

    Each sitting's ``wall_s`` counts from that sitting's start, so a resume shows as ``wall_s`` falling; the run's
    time is the sum of every sitting's last ``wall_s`` (steps dropped at a kill and redone count once)."""
    total = last = 0.0
    for w in _walls(losses_csv):
        if w < last:  # a new sitting
            total += last
        last = w
    return total + last


def probe_seconds(losses_csv, skip: int = PROBE_SKIP) -> float:
    """Seconds per step of a probe run: the mean over its steps after the first ``skip`` (start-up and the first
    steps of a fresh model are slower; the checkpoints every 10 steps are counted, as the real run writes them)."""
    walls = _walls(losses_csv)
    if len(walls) <= skip:
        raise ValueError(f"{losses_csv}: {len(walls)} steps, too few to time")
    return (walls[-1] - walls[skip - 1]) / (len(walls) - skip)


def train_config(split: str, model: str, steps: int, out, pgpr):
    from gpr3d.detection.train import TrainConfig
    from gpr3d.io.coco import CATEGORIES

    only, _, _, held_out = SPLITS[split]
    return TrainConfig(out=str(out), model=model, init=None, kinds=list(CATEGORIES), steps=steps, batch=BATCH,
                       lr=1e-3, warmup=max(1, min(50, steps // 10)), labels=str(Path(pgpr) / "train"),
                       labels_fraction=REAL_SHARE, labels_pattern=only, checkpoint_every=10, freeze=0,
                       augment={"stretch": (0.35, 2.5)} if held_out else None, wall_fraction=0.5 if held_out else 0.0,
                       labels_names=PGPR["names"], labels_kinds=PGPR["kinds"], pixel_map=PGPR["pixel_map"],
                       labels_frequency_hz=PGPR["frequency_hz"])


def _train(cfg) -> dict:
    from gpr3d.detection.train import train_detector
    from gpr3d.simulation.surveys import SurveySource

    wall = SurveySource(cfg.data_seed, profile="wall") if cfg.wall_fraction else None
    return train_detector(cfg, SurveySource(cfg.data_seed), wall_source=wall, progress=False, log=lambda *_: None)


def judged_on(split: str, pgpr, gprmax_n: int):
    """``{set name: records}`` the split's models are judged on."""
    _, test_split, test_only, _ = SPLITS[split]
    sets = {"pgpr": pgpr_records(pgpr, test_split, test_only)}
    path = ROOT / "datasets" / "gprmax_survey.h5"
    if split == "std" and gprmax_n and path.exists():
        from gpr3d.io.packed import labelled_records

        sets["gprmax"] = list(labelled_records(path, n=gprmax_n))
    return sets


def _figures(m: dict) -> dict:
    keep = {k: float(m[k]) for k in METRICS}
    keep.update({k: float(m[k]) for k in ("apex_recall", "false_per_true", "s_per_window")})
    if "by_kind" in m:
        keep["by_kind"] = {k: float(m["by_kind"][k]) for k in METRICS}
    return keep


def _write_json(path: Path, obj) -> None:
    from gpr3d.core.atomic import atomic_write_text

    atomic_write_text(path, json.dumps(obj, indent=1))


def run_unit(split: str, model: str, runs, budget: float, pgpr, gprmax_n: int) -> dict:
    """Probe, train and evaluate one model on one split (each part skipped where it is done already)."""
    import torch

    torch.set_num_threads(1)
    from gpr3d.detection.infer import load_detector
    from gpr3d.detection.evaluate import evaluate_detector

    d = Path(runs) / split / model
    d.mkdir(parents=True, exist_ok=True)
    state_path = d / "unit.json"
    state = json.loads(state_path.read_text()) if state_path.exists() else {}
    if state.get("budget_s", budget) != budget:
        raise SystemExit(f"{d}: trained with --budget {state['budget_s']:g}; use another --runs or the same budget")
    state.update(split=split, model=model, budget_s=budget, host=cpu_name())
    dets = {}
    if model == SHIPPED:
        dets = {"": load_detector(refiner="none"), " + box refiner": load_detector()}
        state["train"] = "synthetic pretraining on a GPU, then P-GPR train on the CPU (default_detector.json)"
    else:
        if "s_per_step" not in state:
            import shutil

            shutil.rmtree(d / "probe", ignore_errors=True)
            _train(train_config(split, model, PROBE_STEPS, d / "probe", pgpr))
            state["s_per_step"] = probe_seconds(d / "probe" / "losses.csv")
            shutil.rmtree(d / "probe", ignore_errors=True)
            _write_json(state_path, state)
        steps = planned_steps(budget, state["s_per_step"])
        weights = d / "weights.pt"
        if not weights.exists():
            from dataclasses import asdict

            from gpr3d.detection.models import count_parameters
            from gpr3d.detection.weights import save_weights

            cfg = train_config(split, model, steps, d / "train", pgpr)
            resumed = (d / "train" / "checkpoint.pt").exists()
            cpu0 = time.process_time()
            res = _train(cfg)
            # the budget's measure: the steps' time on one thread (losses.csv, every sitting); the process's CPU time
            # beside it (set-up included: reading the pictures, compiling the simulator's kernels)
            state["train_s"] = step_seconds(d / "train" / "losses.csv")
            state["cpu_s"] = time.process_time() - cpu0
            if resumed:  # (a killed sitting's CPU time is not known)
                state["cpu_s_of"] = "the last sitting only: the run resumed after a kill"
            state["steps"] = res["steps"]
            state["params_M"] = count_parameters(res["model"]) / 1e6
            save_weights(res["model"], model, cfg.window, weights, kinds=res["kinds"],
                         provenance={"name": model, "command": "python benchmarks/table1_real.py (unit "
                                     f"{split}:{model}, --budget {budget:g})", "config": asdict(cfg),
                                     "train_s": state["train_s"], "device": "cpu, one thread",
                                     "credit": "P-GPR dataset (train split), CC BY 4.0: Yue, Qin, Zhu, Ye, Wang, "
                                               "CIKM '26", "steps_done": res["steps"]})
            _write_json(state_path, state)
        dets = {"": load_detector(weights, refiner="none")}
    state.setdefault("metrics", {})
    for set_name, records in judged_on(split, pgpr, gprmax_n).items():
        for suffix, det in dets.items():
            key = set_name + suffix
            if key in state["metrics"]:
                continue
            t0 = time.perf_counter()
            m = evaluate_detector(det, records)
            state["metrics"][key] = {**_figures(m), "eval_s": time.perf_counter() - t0, "n_records": len(records),
                                     "n_true": int(m["n_true"])}
            _write_json(state_path, state)
    state["done"] = True
    _write_json(state_path, state)
    return state


def _fmt(v, spec=".3f"):
    return "-" if v is None else format(v, spec)


def render(runs, splits, models, budget: float, jobs: int = 1) -> str:
    """The tables of every unit done so far under ``runs`` (the others pending)."""
    units = {}
    for split in splits:
        for model in [*models, SHIPPED] if split == "std" else models:
            p = Path(runs) / split / model / "unit.json"
            units[split, model] = json.loads(p.read_text()) if p.exists() else {}
    hosts = sorted({u["host"] for u in units.values() if u.get("host")})
    out = [f"# Table 1 on real data: every detector trained with one CPU budget ({budget:g} s, one thread)", "",
           f"Host CPU: {', '.join(hosts) or cpu_name()}; each unit one process with one torch thread, "
           f"{jobs} at a time on {os.cpu_count()} cores. From scratch (weights=None), {BATCH} windows a step, "
           f"{REAL_SHARE:.0%} P-GPR train windows, the rest synthetic (see the script's docstring); steps = budget / "
           f"the probe's seconds per step; train s: the steps' time on one thread (the process's CPU time, set-up "
           f"included, in unit.json). Metrics by pycocotools on whole pictures (`Detector.detect`); CPU s per "
           "window: the whole detect (rendering, network, merge), one thread.", ""]
    head = ("| model | params M | steps | train s | metric kind | mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@10 | "
            "AR@100 | recall@0.5 | CPU s/window |")
    for split in splits:
        rows = []
        for model in [*models, SHIPPED] if split == "std" else models:
            u = units[split, model]
            keys = [k for k in (u.get("metrics") or {}) if k.startswith("pgpr")]
            if not u.get("done") or not keys:
                rows.append(f"| {model} | | | | pending | | | | | | | |")
                continue
            for key in keys:
                m = u["metrics"][key]
                name = model + key[len("pgpr"):]
                lead = (f"| {name} | {_fmt(u.get('params_M'), '.1f')} | {u.get('steps', '-')} | "
                        f"{_fmt(u.get('train_s'), '.0f')} |")
                if "by_kind" in m:
                    rows.append(f"{lead} class-averaged | " + " | ".join(_fmt(m["by_kind"][k]) for k in METRICS)
                                + f" | {m['s_per_window']:.3f} |")
                rows.append(f"{lead} class-agnostic | " + " | ".join(_fmt(m[k]) for k in METRICS)
                            + f" | {m['s_per_window']:.3f} |")
        some = next((u for (s, _), u in units.items() if s == split and u.get("metrics", {}).get("pgpr")), None)
        size = (f" ({some['metrics']['pgpr']['n_records']} pictures, {some['metrics']['pgpr']['n_true']} labels)"
                if some else "")
        out += [f"## {SPLIT_TITLE[split]}{size}", "", head, "|---|---|---|---|---|---|---|---|---|---|---|---|", *rows]
        if split == "std":
            out += [f"| {name} | | | | P-GPR test, class-averaged | {m50:.3f} | - | {m:.3f} | - | - | "
                    f"{_fmt(rec)} | |" for name, m50, m, rec in PUBLISHED]
        if split in HELD_OUT_REFERENCE:
            m50, m75, m, ar100, rec, m50_any, rec_any = HELD_OUT_REFERENCE[split]
            name = "stage-3 pretrained (GPU) + 1,000 CPU steps, pgpr_heldout.md"
            out += [f"| {name} | 6.9 | 1000 | | class-averaged | {m50:.3f} | {m75:.3f} | {m:.3f} | - | {ar100:.3f} | "
                    f"{rec:.3f} | |",
                    f"| {name} | 6.9 | 1000 | | class-agnostic | {m50_any:.3f} | - | - | - | - | {rec_any:.3f} | |"]
        out.append("")
    if "std" in splits:
        g = [(model, units["std", model]) for model in [*models, SHIPPED]]
        g = [(model + k[len("gprmax"):], u["metrics"][k]) for model, u in g for k in (u.get("metrics") or {})
             if k.startswith("gprmax")]
        if g:
            n = g[0][1]
            out += [f"## The same models on the held-out gprMax survey set (first {n['n_records']} records, "
                    f"{n['n_true']} targets; class-agnostic; gpr3d's label rule)", "",
                    "| model | mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@100 | recall@0.5 | apex recall | false per "
                    "true |", "|---|---|---|---|---|---|---|---|"]
            out += [f"| {name} | " + " | ".join(_fmt(m[k]) for k in ("mAP@0.5", "mAP@0.75", "mAP", "AR@100",
                                                                      "recall@0.5", "apex_recall", "false_per_true"))
                    + " |" for name, m in g]
            out.append("")
    return "\n".join(out)


def main(argv=None):
    from gpr3d.detection.models import MODELS

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", required=True, help="folder of the units' runs (resumed when run again)")
    p.add_argument("--budget", type=float, default=600.0, help="training seconds each model gets on one thread")
    p.add_argument("--jobs", type=int, default=1,
                   help="units run side by side (one thread each; more than one slows every step)")
    p.add_argument("--splits", nargs="+", default=list(SPLITS), choices=list(SPLITS))
    p.add_argument("--models", nargs="+", default=list(MODELS), choices=list(MODELS))
    p.add_argument("--gprmax", type=int, default=40, help="records of the held-out gprMax survey set (0: none)")
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (train/ and val/)")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--unit", default=None, help=argparse.SUPPRESS)  # SPLIT:MODEL, run by the parent
    args = p.parse_args(argv)
    if not 10 <= args.budget <= 86400:
        p.error(f"--budget must be 10..86400 seconds, got {args.budget:g}")
    if not 1 <= args.jobs <= 16:
        p.error(f"--jobs must be 1..16, got {args.jobs}")
    if args.gprmax < 0:
        p.error(f"--gprmax must be 0 or more records, got {args.gprmax}")
    for name in ("runs", "out"):
        if Path(getattr(args, name)).exists() and not Path(getattr(args, name)).is_dir():
            p.error(f"--{name} {getattr(args, name)}: not a folder")
    if args.unit and (args.unit.partition(":")[0] not in SPLITS
                      or args.unit.partition(":")[2] not in (*MODELS, SHIPPED)):
        p.error(f"--unit {args.unit}: not SPLIT:MODEL")
    for part in ("train", "val"):
        if not (Path(args.pgpr) / part).is_dir():
            p.error(f"--pgpr {args.pgpr}: no {part}/ folder in it (P-GPR's train/ and val/)")
    if not args.unit:  # before any work: pictures that cannot be read, or runs made with another budget
        from gpr3d.core.errors import GPR3DError

        try:
            for split in args.splits:
                only, test_split, test_only, _ = SPLITS[split]
                pgpr_records(args.pgpr, "train", only)
                pgpr_records(args.pgpr, test_split, test_only)
        except GPR3DError as exc:
            p.error(str(exc))
        for path in sorted(Path(args.runs).glob("*/*/unit.json")):
            old = json.loads(path.read_text()).get("budget_s")
            if old is not None and old != args.budget:
                p.error(f"--runs {args.runs}: {path.parent.relative_to(args.runs)} was trained with --budget "
                        f"{old:g}; give that budget or another --runs")
    else:
        split, model = args.unit.split(":", 1)
        run_unit(split, model, args.runs, args.budget, args.pgpr, args.gprmax)
        return 0
    units = [(s, m) for s in args.splits for m in ([*args.models, SHIPPED] if s == "std" else args.models)]
    argv = sys.argv[1:] if argv is None else list(argv)
    failed, lock = [], threading.Lock()

    def one(unit):
        split, model = unit
        env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
        cmd = [sys.executable, __file__, "--unit", f"{split}:{model}", "--runs", args.runs, "--budget",
               str(args.budget), "--gprmax", str(args.gprmax), "--pgpr", args.pgpr]
        t0 = time.perf_counter()
        r = subprocess.run(cmd, env=env, capture_output=True, text=True)
        tail = (r.stderr.strip().splitlines() or [""])[-1]
        print(f"{split}:{model} {'done' if r.returncode == 0 else 'FAILED: ' + tail} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
        with lock:
            if r.returncode:
                failed.append(f"{split}:{model}")
            write_table(args.out, "table1_real.md", render(args.runs, args.splits, args.models, args.budget, args.jobs),
                        "table1_real.py", argv)

    with ThreadPoolExecutor(args.jobs) as pool:
        list(pool.map(one, units))
    if failed:
        sys.exit(f"table1_real.py: {len(failed)} unit(s) failed: {', '.join(failed)}; run again to retry")
    return 0


if __name__ == "__main__":
    sys.exit(main())
