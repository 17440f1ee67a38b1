"""Mutation testing of gpr3d's core with mutmut (issue 13): one module at a time, with the tests of its package.

For each module named (default: all of ``MODULES``) this copies ``src/`` and ``tests/`` into
``build/mutation/<module>/``, writes a ``pyproject.toml`` there that tells mutmut to mutate that one file and
run the tests of its package, runs ``mutmut run``, and reads back what each mutant did. Survivors listed in
``tools/mutation_equivalents.toml`` (the removed and the added line, and why the two behave the same) count as
equivalent; the score is killed (or timed out) over all mutants that are not equivalent. Each module's result
(with the commit and CPU it was measured on) is kept in ``benchmarks/results/mutation/<module>.json``, and the
report ``benchmarks/results/mutation.md`` (``--out``) is made from all of them: the table and every surviving
mutant's diff. The exit code is 1 when a module run now scores below ``--fail-under``.

    python tools/mutation.py processing.dewow io.dt1        # some modules
    python tools/mutation.py --changed main                 # the modules that differ from a git revision
    python tools/mutation.py --guard                        # the CI guard (below)
    python tools/mutation.py                                # all of MODULES (long: see the report's times)

The guard (``--guard``, run by ``tests/tools/test_mutation_guard.py``) reads the stored results, each with the
commit it was measured at, and re-runs the modules whose code has changed since theirs (their syntax trees,
docstrings left out, which mutmut never mutates): a scored module cannot land
with a score below ``--fail-under``. Its report goes to ``build/mutation/guard.md``; the stored results stay.
It is bounded (``--budget-s``, 300 s by the stored run times): beyond that it fails and names the command whose
results, committed, make the guard cheap again.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MUTMUT = [sys.executable, "-m", "mutmut"]

#: module (under gpr3d) -> the tests that judge it (default: its package's test folder)
MODULES = {
    "io.dt1": None, "io.dzt": None, "io.rd3": None, "io.gprmax": None, "io.segy": None, "io.hdf5": None,
    "core.atomic": ["tests/core/test_atomic.py", "tests/io/test_detections.py", "tests/io/test_resultdir.py"],
    "core.training": ["tests/core/test_training.py", "tests/detection/test_train_by_hand.py",
                      "tests/inversion/test_depthnet_by_hand.py"],  # (the engine under both models' loops)
    "io.volume": None, "io.detections": None, "io.coco": None, "io.resultdir": ["tests/io/test_resultdir.py"],
    "io._common": None, "io.registry": None,
    # (the other tests of tests/io that reach the trajectory readers are slow: rosbag, inertial)
    "io.trajectory": ["tests/io/test_trajectory.py", "tests/io/test_track.py"],
    "io.inertial": ["tests/io/test_inertial.py", "tests/io/test_inertial_by_hand.py"], "io.rosbag": ["tests/io/test_rosbag.py", "tests/io/test_rosbag_by_hand.py", "-k", "not rgbd_bag"],
    "io.userlabels": ["tests/io/test_userlabels.py", "tests/io/test_userlabels_by_hand.py"],
    "io.yolo": ["tests/io/test_yolo.py"], "io.labelled": ["tests/io/test_labelled.py", "tests/io/test_yolo.py"], "io.packed": ["tests/io/test_packed.py"],
    "io.weights": ["tests/io/test_weights.py"], "io.onnxweights": ["tests/io/test_onnxweights.py"],
    "processing.dewow": None, "processing.background": None, "processing.gain": None, "processing.filters": None,
    "processing.envelope": None, "processing.resample": None, "processing.timezero": None,
    "processing.steps": None, "processing.cscan": None,
    "processing.picking": ["tests/processing"],
    "processing.image": ["tests/processing/test_image.py", "tests/detection/test_windows_by_hand.py"],
    "processing.analytic": ["tests/processing/test_analytic.py"],
    "processing.signal": ["tests/processing/test_signal.py"],
    "migration.operator": None,
    "migration.masking": ["tests/migration/test_masking.py"],
    "migration.velocity": ["tests/migration/test_velocity.py", "-k", "not oblique"],
    "migration.targets": None, "migration.metrics": None,
    "migration.profile": None, "migration.traditional": None, "migration.reconstruct": None,
    "migration.refine": ["tests/migration/test_refine.py"],
    # less the tests that start a real Dask client: in mutmut's forked children its event loop hangs (the parent's
    # loop thread is gone); the Dask plumbing is checked against a recording stand-in (test_sitetiles_by_hand.py)
    "migration.sitetiles": ["tests/migration/test_sitetiles.py", "tests/migration/test_sitetiles_by_hand.py", "-k",
                            "not dask and not given_in_process_client"],
    "migration.rtm": ["tests/migration/test_rtm.py", "tests/migration/test_rtm_by_hand.py"],
    # numba kernels: mutmut leaves decorated functions alone, so only their plain-Python helpers are mutated
    "migration._kernels": ["tests/migration/test_operator.py", "tests/migration/test_kernels_by_hand.py"], "migration._simd": ["tests/migration/test_simd_by_hand.py"],
    "simulation.forward": ["tests/simulation/test_forward.py", "tests/simulation/test_forward_by_hand.py"],
    "simulation.labels": ["tests/simulation/test_labels.py"],
    # the packages beside the pipeline: each module with the test files that import it (less the slow training,
    # ROS-bag and CLI ones that only pass through)
    "pose.eskf": ["tests/pose/test_eskf_by_hand.py", "tests/pose/test_eskf_driver_by_hand.py", "tests/pose/test_eskf.py", "-k",
                  "by_hand or noise_free or bad_inputs or bridges or camera_motion or forward_fusion or fed_as"], "pose.sync": ["tests/pose/test_sync.py"],
    "pose.metrics": ["tests/pose/test_metrics.py"],
    "detection.models": ["tests/detection/test_models_by_hand.py", "tests/detection/test_kinds.py"],
    "detection.kindheads": ["tests/detection/test_kinds.py"],
    "detection.infer": ["tests/detection/test_infer_by_hand.py", "tests/detection/test_kinds.py",
                        "tests/detection/test_refine.py::test_the_detector_refines_its_merged_boxes_before_it_reports_them",
                        "tests/detection/test_refine.py::test_only_the_boxes_reported_are_refined",
                        "tests/detection/test_refine.py::test_the_refiner_sees_the_record_as_the_windows_render_it_and_is_timed",
                        "tests/detection/test_refine.py::test_how_a_refiner_is_applied_is_checked_in_one_line",
                        "tests/detection/test_refine.py::test_a_whole_refiner_s_box_past_the_first_trace_gives_its_apex_as_its_centre",
                        "tests/detection/test_refine.py::test_the_detector_multiplies_refined_scores_by_the_quality_to_its_weight_and_says_how",
                        "tests/detection/test_refine.py::test_a_box_the_refiner_moves_onto_a_surer_one_is_scored_lower",
                        "tests/detection/test_refine.py::test_the_detector_names_the_fine_stage_that_moved_its_boxes"],
    "detection.refine": ["tests/detection/test_refine.py", "-m", "not slow"],
    "detection.calibration": ["tests/detection/test_calibration.py", "tests/detection/test_infer_by_hand.py"],
    "detection.ort": ["tests/detection/test_onnx_runtime.py", "tests/detection/test_onnx_int8.py"],
    "detection.train": ["tests/detection/test_train_by_hand.py", "tests/detection/test_kinds.py"],
    "detection.weights": ["tests/detection/test_weights_train.py", "tests/detection/test_kinds.py", "-k",
                          "round_trip or bad_weight or default_weights or messages_in_full or test_kinds"],
    "pose.imu": ["tests/pose/test_imu.py"],
    "pose.graph": ["tests/pose/test_graph_by_hand.py"], "pose.vo": ["tests/pose/test_vo_by_hand.py", "tests/pose/test_vo.py", "-k", "by_hand or bad_frames or plain_floor"],
    "pose.render": ["tests/pose/test_render.py", "tests/pose/test_render_by_hand.py"],
    "pose.rig": ["tests/pose/test_rig_by_hand.py"],
    "inversion.hyperbola": ["tests/inversion/test_hyperbola.py"],
    "inversion.depthnet": ["tests/inversion/test_depthnet_by_hand.py", "tests/inversion/test_depthnet.py", "-k",
                           "not training_learns"],
    "inversion.estimate": ["tests/inversion/test_estimate.py", "tests/inversion/test_estimate_by_hand.py"],
    "inversion.evaluate": ["tests/inversion/test_estimate.py", "tests/inversion/test_evaluate_by_hand.py"],
    "detection.windows": ["tests/detection/test_windows.py", "tests/detection/test_windows_by_hand.py", "tests/detection/test_kinds.py"],
    "detection.evaluate": ["tests/detection/test_evaluate.py", "tests/detection/test_evaluate_by_hand.py", "tests/detection/test_kinds.py"],
    "detection.data": ["tests/detection/test_data_by_hand.py", "tests/detection/test_kinds.py",
                       "tests/detection/test_augment.py"],
    "detection.augment": ["tests/detection/test_augment.py"],
    "core.timing": ["tests/core/test_timing.py"],
    "core.warmup": ["tests/core/test_warmup.py", "tests/cli/test_warm_cli.py", "-k", "not first_reconstruct"],
}


#: the io modules' tests, less the slow ones that only pass through the readers (ROS bags, IMU logs, user labels):
#: a mutant of a helper every reader calls would otherwise run them all
IO_TESTS = ["tests/io", "--ignore=tests/io/test_rosbag.py", "--ignore=tests/io/test_inertial.py",
            "--ignore=tests/io/test_userlabels.py"]


#: the migration modules' tests, less the Dask-cluster ones of site tiles: a mutant's forked test run that starts a
#: cluster of worker processes can leave its scheduler behind, and mutmut then waits for it
MIGRATION_TESTS = ["tests/migration", "--ignore=tests/migration/test_sitetiles.py"]


def tests_for(module: str) -> list[str]:
    given = MODULES.get(module)
    if given:
        return given
    if module.startswith("io."):
        return IO_TESTS
    if module.startswith("migration."):
        return MIGRATION_TESTS
    return [f"tests/{module.split('.')[0]}"]


def source_of(module: str) -> Path:
    return Path("src/gpr3d") / (module.replace(".", "/") + ".py")


def load_equivalents(path: Path) -> dict:
    """``{module: [(removed line, added line, reason), ...]}`` (lines compared without surrounding spaces)."""
    if not path.exists():
        return {}
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    out = {}

    def walk(node, names):  # [[processing.dewow.mutant]] nests as {"processing": {"dewow": {"mutant": [...]}}}
        for key, val in node.items():
            if key == "mutant":
                out[".".join(names)] = [(r["removed"].strip(), r["added"].strip(), r["reason"]) for r in val]
            elif isinstance(val, dict):
                walk(val, [*names, key])

    walk(data, [])
    return out


def _diff(workdir: Path, name: str) -> tuple[str, str]:
    """The removed and the added line of mutant ``name`` (several lines joined by " ¶ ")."""
    r = subprocess.run([*MUTMUT, "show", name], cwd=workdir, capture_output=True, text=True)
    minus = [ln[1:].strip() for ln in r.stdout.splitlines() if ln.startswith("-") and not ln.startswith("---")]
    plus = [ln[1:].strip() for ln in r.stdout.splitlines() if ln.startswith("+") and not ln.startswith("+++")]
    return " ¶ ".join(minus), " ¶ ".join(plus)


def fork_safe_tqdm(conftest: Path) -> None:
    """Append to the copied tests' ``conftest`` a per-process tqdm lock and no monitor thread.

    tqdm guards its bars with a process-shared semaphore, created once in mutmut's parent and inherited by every
    forked child: a child killed at its time limit while drawing a bar (a mutant that loops) leaves it held, and
    every later child that makes a bar then waits on it until its own limit, counted as killed. A lock of each
    process's own (and no monitor thread, which a fork does not carry) keeps one child's death from the others.
    """
    with open(conftest, "a", encoding="utf-8") as f:
        f.write("\n\nimport threading as _threading\n\nimport tqdm as _tqdm\n\n"
                "_tqdm.tqdm.set_lock(_threading.RLock())\n_tqdm.tqdm.monitor_interval = 0\n")


def run_module(module: str, *, max_children: int, equivalents: list, keep: bool) -> dict:
    src = ROOT / source_of(module)
    if not src.exists():
        raise SystemExit(f"{module}: no such module ({src})")
    work = ROOT / "build" / "mutation" / module
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(ROOT / "src", work / "src", ignore=ignore)
    shutil.copytree(ROOT / "tests", work / "tests", ignore=ignore)
    tests = tests_for(module)
    cfg = (
        "[tool.mutmut]\n"
        'source_paths = ["src"]\n'
        f'only_mutate = ["{source_of(module).as_posix()}"]\n'
        f"pytest_add_cli_args_test_selection = {json.dumps(tests)}\n"
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-q", "-x"]\n'
        "\n[tool.pytest.ini_options]\n"
        'testpaths = ["tests"]\n'
        'filterwarnings = ["ignore::DeprecationWarning"]\n'
    )
    (work / "pyproject.toml").write_text(cfg, encoding="utf-8")
    fork_safe_tqdm(work / "tests" / "conftest.py")
    # the copies' tests must still find the real recordings beside the repository
    # numba's OpenMP threading layer raises SIGTERM in a process forked after it ran a parallel kernel, and mutmut
    # forks every mutant's run from the process that ran the tests once: the workqueue layer survives the fork
    # (and one OpenMP thread keeps torch's pool out of the forked children)
    env = dict(os.environ, PYTHONPATH=str(work), NUMBA_NUM_THREADS="1", NUMBA_THREADING_LAYER="workqueue",
               OMP_NUM_THREADS="1", GPR3D_FUZZ_EXAMPLES="10",
               GPR3D_REAL_DATA=os.environ.get("GPR3D_REAL_DATA", str(ROOT.parent / "shared" / "data" / "real")))
    t = time.perf_counter()
    r = subprocess.run([*MUTMUT, "run", "--max-children", str(max_children)], cwd=work, env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t
    subprocess.run([*MUTMUT, "export-cicd-stats"], cwd=work, env=env, capture_output=True, text=True)
    stats_file = work / "mutants" / "mutmut-cicd-stats.json"
    if r.returncode != 0 or not stats_file.exists():
        tail = (r.stdout + r.stderr)[-1500:]
        return {"module": module, "error": tail.strip().splitlines()[-1] if tail.strip() else f"exit {r.returncode}",
                "wall_s": wall}
    stats = json.loads(stats_file.read_text())
    res = subprocess.run([*MUTMUT, "results"], cwd=work, env=env, capture_output=True, text=True).stdout
    alive = [m.group(1) for m in re.finditer(r"^\s*(\S+): (survived|no tests)", res, flags=re.M)]
    survivors, equivalent = [], []
    for name in alive:
        removed, added = _diff(work, name)
        why = next((w for a, b, w in equivalents if a == removed and b == added), None)
        (equivalent if why else survivors).append({"name": name, "removed": removed, "added": added, "why": why})
    total = stats["total"] - stats.get("skipped", 0)
    killed = stats["killed"] + stats.get("timeout", 0) + stats.get("segfault", 0)
    judged = total - len(equivalent)
    if not keep:
        shutil.rmtree(work, ignore_errors=True)
    return {"module": module, "tests": tests, "total": total, "killed": killed, "survived": len(survivors),
            "equivalent": len(equivalent), "suspicious": stats.get("suspicious", 0),
            "timed_out": stats.get("timeout", 0),
            "score": killed / judged if judged else 1.0, "wall_s": wall, "survivors": survivors,
            "equivalents": equivalent}


def changed_modules(base: str) -> list[str]:
    # the working tree against ``base``: committed and uncommitted changes alike
    r = subprocess.run(["git", "diff", "--name-only", base, "--", "src/gpr3d"], cwd=ROOT, capture_output=True,
                       text=True, check=True)
    names = [p[len("src/gpr3d/"):-3].replace("/", ".") for p in r.stdout.split() if p.endswith(".py")]
    return [n for n in names if n in MODULES]


def code_of(text: str) -> str:
    """A module's code as the mutants see it: its syntax tree without the docstrings (comments and layout are not
    in the tree either). mutmut leaves docstrings alone, so a change to them alone cannot change a result."""
    tree = ast.parse(text)
    for node in ast.walk(tree):
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body
                and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)
                and isinstance(node.body[0].value.value, str)):
            node.body = node.body[1:] or [ast.Pass()]
    return ast.dump(tree)


def code_changed(module: str, commit: str) -> bool:
    """Whether ``module``'s code (:func:`code_of`) in the working tree differs from its code at ``commit``."""
    r = subprocess.run(["git", "show", f"{commit}:{source_of(module)}"], cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:  # (new since the commit, or not in this checkout)
        return True
    return code_of(r.stdout) != code_of((ROOT / source_of(module)).read_text(encoding="utf-8"))


def head_commit() -> str | None:
    r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return r.stdout.strip() if r.returncode == 0 else None


STORE = ROOT / "benchmarks" / "results" / "mutation"


def cpu_label() -> str:
    try:
        import llvmlite.binding as llb

        return f"{llb.get_host_cpu_name()}, {os.cpu_count()} cores"
    except Exception:  # noqa: BLE001 - the CPU name is a label only
        return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"


def save_result(row: dict, store: Path, command: str) -> Path:
    """Keep one module's result, with the commit, CPU and command it was measured with."""
    store.mkdir(parents=True, exist_ok=True)
    rec = {**row, "commit": head_commit(), "cpu": cpu_label(), "command": command,
           "date": time.strftime("%Y-%m-%d", time.gmtime())}
    path = store / f"{row['module']}.json"
    tmp = path.with_suffix(".part")
    tmp.write_text(json.dumps(rec, indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def load_results(store: Path) -> list[dict]:
    """The stored results, in the order of ``MODULES`` (then any others by name)."""
    rows = [json.loads(p.read_text(encoding="utf-8")) for p in sorted(store.glob("*.json"))] if store.exists() else []
    order = {m: i for i, m in enumerate(MODULES)}
    return sorted(rows, key=lambda r: (order.get(r["module"], len(order)), r["module"]))


def reclassify(row: dict, equivalents: dict) -> dict:
    """A stored result with the survivors that the equivalents file lists now counted as equivalent (the list
    matches mutants by their diff, so no re-run is needed); the stored file itself stays as measured."""
    if "error" in row or not row.get("survivors"):
        return row
    listed = equivalents.get(row["module"], [])
    still, moved = [], []
    for s in row["survivors"]:
        why = next((w for a, b, w in listed if a == s["removed"] and b == s["added"]), None)
        if why:
            moved.append({**s, "why": why})
        else:
            still.append(s)
    if not moved:
        return row
    equiv = [*row.get("equivalents", []), *moved]
    judged = row["total"] - len(equiv)
    return {**row, "survivors": still, "survived": len(still), "equivalents": equiv, "equivalent": len(equiv),
            "score": row["killed"] / judged if judged else 1.0}


def guarded(store: Path) -> dict:
    """``{module: commit}`` of the stored results."""
    return {r["module"]: r.get("commit") for r in load_results(store)}


def write_report(rows: list[dict], path: Path, command: str) -> None:
    """The table (score per module, with the host CPU and commit each was measured on) and every survivor's and
    listed equivalent's diff."""
    lines = ["mutmut, one module at a time with the tests of its package; score = killed / (mutants - equivalent)", "",
             "| module | mutants | killed | of which timed out | survived | equivalent | unclassified | score | time (s) | "
             "host CPU | commit |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        where = f"{r.get('cpu', cpu_label())} | {(r.get('commit') or head_commit() or '?')[:10]}"
        if "error" in r:
            lines.append(f"| {r['module']} | error: {r['error'][:80]} | | | | | | | {r['wall_s']:.0f} | {where} |")
            continue
        lines.append(f"| {r['module']} | {r['total']} | {r['killed']} | {r.get('timed_out', '?')} | {r['survived']} | "
                     f"{r['equivalent']} | "
                     f"{r.get('suspicious', 0)} | {100 * r['score']:.1f} % | {r['wall_s']:.0f} | {where} |")
    done = [r for r in rows if "error" not in r]
    if done:
        tot = sum(r["total"] - r["equivalent"] for r in done)
        counted = [r for r in done if "timed_out" in r]
        timed = f"{sum(r['timed_out'] for r in counted)}" + (
            "" if len(counted) == len(done) else f" (in {len(counted)} modules)")
        lines.append(f"| **all {len(done)}** | {sum(r['total'] for r in done)} | {sum(r['killed'] for r in done)} | "
                     f"{timed} | "
                     f"{sum(r['survived'] for r in done)} | {sum(r['equivalent'] for r in done)} | "
                     f"{sum(r.get('suspicious', 0) for r in done)} | "
                     f"{100 * sum(r['killed'] for r in done) / max(tot, 1):.1f} % | "
                     f"{sum(r['wall_s'] for r in done):.0f} | | |")
        lines += ["", "of which timed out: killed by mutmut's time limit, not by a failing test ('?': measured before "
                      "the count was kept)"]
        lines += ["", "unclassified: mutants whose test run ended with an exit status mutmut does not classify "
                      "('suspicious'): neither killed nor survived, and counted against the score"]
        lines += ["", "Not yet scored: " + (", ".join(m for m in MODULES if m not in {r['module'] for r in rows})
                                           or "none")]
    for r in rows:
        if r.get("survivors"):
            lines += ["", f"### {r['module']}: surviving mutants", ""]
            lines += [f"- `{s['removed']}` -> `{s['added']}`" for s in r["survivors"]]
        if r.get("equivalents"):
            lines += ["", f"### {r['module']}: equivalent mutants (tools/mutation_equivalents.toml)", ""]
            lines += [f"- `{s['removed']}` -> `{s['added']}`: {s['why']}" for s in r["equivalents"]]
    lines += ["", f"command: {command} (each module's own command is in benchmarks/results/mutation/<module>.json; "
                  "the tree mutated is its commit plus any uncommitted changes)", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part")
    tmp.write_text("\n".join(lines), encoding="utf-8")
    tmp.replace(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("modules", nargs="*", help="modules under gpr3d (processing.dewow, io.dt1, ...)")
    ap.add_argument("--changed", metavar="BASE", help="the modules that differ from git revision BASE")
    ap.add_argument("--max-children", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--fail-under", type=float, default=85.0, help="score (%%) every module must reach")
    ap.add_argument("--out", default=str(ROOT / "benchmarks/results/mutation.md"))
    ap.add_argument("--equivalents", default=str(ROOT / "tools/mutation_equivalents.toml"))
    ap.add_argument("--keep", action="store_true", help="keep build/mutation/<module>/ (to browse with mutmut)")
    ap.add_argument("--guard", action="store_true",
                    help="re-run the scored modules that changed since their commits; report to build/")
    ap.add_argument("--store", default=str(STORE), help="folder of the per-module results")
    ap.add_argument("--report", action="store_true",
                    help="only remake the report from the stored results (with the equivalents listed now)")
    ap.add_argument("--budget-s", type=float, default=300.0,
                    help="--guard: the most seconds of re-runs (by the stored times) it does; over it, it fails and "
                         "names the command that refreshes the stored results")
    args = ap.parse_args(argv)
    if args.max_children < 1:
        ap.error(f"--max-children must be >= 1, got {args.max_children}")
    store = Path(args.store)
    if args.report:
        eq = load_equivalents(Path(args.equivalents))
        rows = [reclassify(r, eq) for r in load_results(store)]
        write_report(rows, Path(args.out), "python tools/mutation.py --report")
        print(f"report: {args.out}")
        return 0
    if args.guard:
        listed = guarded(store)
        if not listed:
            print(f"{store}: no stored results to guard")
            return 0
        mods = []
        for module, commit in listed.items():
            try:
                if commit and module in changed_modules(commit) and code_changed(module, commit):
                    mods.append(module)  # (a change to docstrings or comments alone is not re-run)
            except subprocess.CalledProcessError:
                print(f"{module}: commit {commit[:10]} is not in this checkout: not compared")
        args.out = str(ROOT / "build" / "mutation" / "guard.md")
        print(f"guard: {len(listed)} modules scored; changed since their commits: {', '.join(mods) or 'none'}")
        wall = {r["module"]: r.get("wall_s", 0.0) for r in load_results(store)}
        need = sum(wall.get(m, 0.0) for m in mods)
        if need > args.budget_s:
            print(f"guard: re-running {', '.join(mods)} takes about {need:.0f} s, over the {args.budget_s:g} s budget: "
                  f"run python tools/mutation.py {' '.join(mods)} and commit benchmarks/results/mutation/")
            return 1
    else:
        mods = changed_modules(args.changed) if args.changed else (args.modules or list(MODULES))
    unknown = [m for m in mods if not (ROOT / source_of(m)).exists()]
    if unknown:
        ap.error(f"no such module: {', '.join(unknown)}")
    if not mods:
        print("no core module changed")
        return 0
    eq = load_equivalents(Path(args.equivalents))
    rows = []
    command = "python tools/mutation.py " + " ".join(argv if argv is not None else sys.argv[1:])
    for m in mods:
        row = run_module(m, max_children=args.max_children, equivalents=eq.get(m, []), keep=args.keep)
        rows.append(row)
        if not args.guard and "error" not in row:
            save_result(row, store, f"python tools/mutation.py {m}")
        msg = (f"error: {row['error']}" if "error" in row else
               f"{row['total']} mutants, {row['killed']} killed, {row['survived']} survived, {row['equivalent']} "
               f"equivalent: {100 * row['score']:.1f} %")
        print(f"{m:28s} {msg} ({row['wall_s']:.0f} s)", flush=True)
    write_report(rows if args.guard else [reclassify(r, eq) for r in load_results(store)], Path(args.out), command)
    low = [r["module"] for r in rows if "error" in r or 100 * r["score"] < args.fail_under]
    if low:
        print(f"below {args.fail_under:g} %: {', '.join(low)}")
    return 1 if low else 0


if __name__ == "__main__":
    sys.exit(main())
