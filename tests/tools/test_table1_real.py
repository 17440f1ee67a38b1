"""benchmarks/table1_real.py: one CPU budget for every model (steps from a timed probe, time counted across
resumes), the splits' recipes, the table's rows, one-line refusals, and a real unit on a few P-GPR pictures."""

import json
import shutil
from pathlib import Path

import pytest

from tests.tools._script import load_script, refusal

PGPR = Path(__file__).resolve().parents[3] / "shared" / "data" / "real" / "pgpr_1600MHz"


@pytest.fixture(scope="module")
def mod():
    return load_script("benchmarks/table1_real.py")


def _losses(path, walls):
    path.write_text("step,lr,loss,wall_s,terms\n" + "".join(f"{i + 1},0.001,1.0,{w},x=1\n"
                                                             for i, w in enumerate(walls)))
    return path


def test_a_resumed_run_counts_every_sitting_once(mod, tmp_path):
    # two sittings: 3.0 s, then a resume whose clock starts again (1.5 s): 4.5 s in all
    assert mod.step_seconds(_losses(tmp_path / "l.csv", [1.0, 2.0, 3.0, 0.5, 1.5])) == pytest.approx(4.5)
    assert mod.step_seconds(_losses(tmp_path / "m.csv", [0.7, 1.9, 3.2])) == pytest.approx(3.2)


def test_the_probe_times_the_steps_after_its_first_ones(mod, tmp_path):
    # the first four steps are slow (start-up, a fresh model); then 1 s each, a checkpoint's 2 s among them
    walls = [5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 13.0, 14.0]
    assert mod.PROBE_SKIP == 4 and mod.probe_seconds(_losses(tmp_path / "l.csv", walls)) == pytest.approx(1.5)
    assert mod.probe_seconds(_losses(tmp_path / "m.csv", [9.0, 9.5, 10.0, 12.5]), skip=2) == pytest.approx(1.5)
    with pytest.raises(ValueError, match="too few"):
        mod.probe_seconds(_losses(tmp_path / "n.csv", [1.0, 2.0, 3.0, 4.0]))


def test_the_budget_buys_steps_and_never_fewer_than_the_floor(mod):
    assert mod.planned_steps(600, 1.25) == 480
    assert mod.planned_steps(600, 7.0) == 85
    assert mod.planned_steps(600, 100.0) == mod.MIN_STEPS == 20


def test_each_split_trains_on_its_radar_with_its_recipe(mod, tmp_path):
    std = mod.train_config("std", "ssdlite", 300, tmp_path / "a", "/p")
    air = mod.train_config("air", "frcnn_r18", 300, tmp_path / "b", "/p")
    iecas = mod.train_config("iecas", "fcos_r18", 20, tmp_path / "c", "/p")
    assert (std.model, std.init, std.labels, std.labels_pattern, std.labels_fraction) == \
        ("ssdlite", None, "/p/train", None, 0.75)
    assert std.augment is None and std.wall_fraction == 0 and std.warmup == 30 and std.batch == 4
    assert (air.labels_pattern, air.wall_fraction, list(air.augment["stretch"])) == ("AIR_*", 0.5, [0.35, 2.5])
    assert (iecas.labels_pattern, iecas.warmup) == ("IECAS_*", 2)
    assert {"rebar", "pvc_pipe"} <= set(std.kinds) and std.labels_kinds == "pipe=pvc_pipe"
    # the held-out models are judged on the other radar, train and val alike
    assert mod.SPLITS["air"][1:3] == ("train,val", "IECAS_*") and mod.SPLITS["iecas"][1:3] == ("train,val", "AIR_*")


def test_the_table_gives_each_done_unit_its_figures_and_the_rest_pending(mod, tmp_path):
    fig = dict(zip(mod.METRICS, (0.61, 0.22, 0.31, 0.41, 0.51, 0.91)))
    avg = dict(zip(mod.METRICS, (0.52, 0.12, 0.21, 0.32, 0.42, 0.82)))
    unit = {"done": True, "host": "testcpu", "params_M": 6.9, "steps": 529, "train_s": 598.4,
            "metrics": {"pgpr": {**fig, "by_kind": avg, "s_per_window": 0.123, "apex_recall": 0, "false_per_true": 0,
                                 "n_records": 56, "n_true": 313},
                        "gprmax": {**fig, "apex_recall": 0.7, "false_per_true": 0.25, "s_per_window": 0.2,
                                   "n_records": 40, "n_true": 222}}}
    (tmp_path / "std" / "frcnn_lean").mkdir(parents=True)
    (tmp_path / "std" / "frcnn_lean" / "unit.json").write_text(json.dumps(unit))
    text = mod.render(tmp_path, ["std", "air"], ["frcnn_lean", "ssdlite"], 600)
    lines = text.splitlines()
    assert "| frcnn_lean | 6.9 | 529 | 598 | class-averaged | 0.520 | 0.120 | 0.210 | 0.320 | 0.420 | 0.820 | 0.123 |" \
        in lines
    assert "| frcnn_lean | 6.9 | 529 | 598 | class-agnostic | 0.610 | 0.220 | 0.310 | 0.410 | 0.510 | 0.910 | 0.123 |" \
        in lines
    assert "| frcnn_lean | 0.610 | 0.220 | 0.310 | 0.510 | 0.910 | 0.700 | 0.250 |" in lines  # the gprMax table
    assert "(56 pictures, 313 labels)" in text and "first 40 records, 222 targets" in text
    assert lines.count("| ssdlite | | | | pending | | | | | | | |") == 2  # std and air
    assert lines.count("| frcnn_lean | | | | pending | | | | | | | |") == 1  # air only
    assert "| shipped default | | | | pending" in text and "Faster R-CNN (pretrained, published)" in text
    # the held-out split carries its pretrained reference (pgpr_heldout.md), the standard one does not
    ref = [ln for ln in lines if ln.startswith("| stage-3 pretrained")]
    assert ref == ["| stage-3 pretrained (GPU) + 1,000 CPU steps, pgpr_heldout.md | 6.9 | 1000 | | class-averaged | "
                   "0.410 | 0.045 | 0.139 | - | 0.271 | 0.693 | |",
                   "| stage-3 pretrained (GPU) + 1,000 CPU steps, pgpr_heldout.md | 6.9 | 1000 | | class-agnostic | "
                   "0.553 | - | - | - | - | 0.818 | |"]
    assert lines.index(ref[0]) > next(i for i, ln in enumerate(lines) if ln.startswith("## device held out: AIR"))


@pytest.mark.parametrize("args, says", [
    (("--budget", "5"), "--budget must be 10..86400 seconds, got 5"),
    (("--jobs", "0"), "--jobs must be 1..16, got 0"),
    (("--gprmax", "-1"), "--gprmax must be 0 or more records, got -1"),
    (("--pgpr", "{tmp}/absent"), "--pgpr {tmp}/absent: no train/ folder in it (P-GPR's train/ and val/)"),
    (("--pgpr", "{tmp}"), "not a YOLO dataset: no data.yaml and no images/ folder"),
    (("--models", "yolo"), "argument --models: invalid choice: 'yolo'"),
    (("--out", "{tmp}/file.txt"), "--out {tmp}/file.txt: not a folder"),
    (("--runs", "{tmp}/file.txt"), "--runs {tmp}/file.txt: not a folder"),
    (("--unit", "std:yolo"), "--unit std:yolo: not SPLIT:MODEL"),
])
def test_a_wrong_setting_is_one_line_naming_it(tmp_path, args, says):
    (tmp_path / "train").mkdir()
    (tmp_path / "val").mkdir()
    (tmp_path / "file.txt").write_text("x")
    base = ["--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "out")]  # (a setting given after wins)
    given = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert says.replace("{tmp}", str(tmp_path)) in refusal("table1_real.py", *base, *given)
    assert not (tmp_path / "runs").exists() and not (tmp_path / "out").exists()


def _few_pictures(dest, names):
    for part, stems in names.items():
        for sub, ext in (("images", ".png"), ("labels", ".txt")):
            (dest / part / sub).mkdir(parents=True, exist_ok=True)
            for stem in stems:
                shutil.copy(PGPR / part / sub / (stem + ext), dest / part / sub)


@pytest.mark.skipif(not PGPR.is_dir(), reason="P-GPR is not in ../shared/data/real")
def test_runs_made_with_another_budget_are_refused_before_any_work(tmp_path):
    _few_pictures(tmp_path / "p", {"train": [p.stem for p in sorted((PGPR / "train" / "images").glob("*.png"))[:1]],
                                  "val": [p.stem for p in sorted((PGPR / "val" / "images").glob("*.png"))[:1]]})
    (tmp_path / "runs" / "std" / "ssdlite").mkdir(parents=True)
    (tmp_path / "runs" / "std" / "ssdlite" / "unit.json").write_text(json.dumps({"budget_s": 600.0}))
    last = refusal("table1_real.py", "--runs", str(tmp_path / "runs"), "--pgpr", str(tmp_path / "p"), "--splits",
                   "std", "--budget", "300", "--out", str(tmp_path / "out"))
    assert "std/ssdlite was trained with --budget 600; give that budget or another --runs" in last


@pytest.mark.slow
@pytest.mark.skipif(not PGPR.is_dir(), reason="P-GPR is not in ../shared/data/real")
def test_a_unit_trains_its_budget_judges_the_other_pictures_and_is_not_redone(mod, tmp_path):
    train = sorted((PGPR / "train" / "images").glob("IECAS_*.png"))[:2]
    val = sorted((PGPR / "val" / "images").glob("IECAS_*.png"))[:1]
    _few_pictures(tmp_path / "p", {"train": [p.stem for p in train], "val": [p.stem for p in val]})
    state = mod.run_unit("std", "ssdlite", tmp_path / "runs", 10.0, tmp_path / "p", 0)
    assert state["done"] and state["steps"] == mod.planned_steps(10.0, state["s_per_step"])
    assert 0 < state["train_s"] and 0 < state["cpu_s"]
    n_true = sum(1 for line in (tmp_path / "p" / "val" / "labels" / (val[0].stem + ".txt")).read_text().splitlines()
                 if line.strip())
    m = state["metrics"]["pgpr"]
    assert (m["n_records"], m["n_true"]) == (1, n_true) and set(m["by_kind"]) == set(mod.METRICS)
    assert all(0 <= m[k] <= 1 for k in mod.METRICS) and m["s_per_window"] > 0
    from gpr3d.detection.weights import load_weights

    model, _, prov = load_weights(tmp_path / "runs" / "std" / "ssdlite" / "weights.pt")
    assert prov["steps_done"] == state["steps"] and "P-GPR" in prov["credit"]
    assert {"rebar", "pvc_pipe"} <= set(model.gpr3d_kinds)
    weights = tmp_path / "runs" / "std" / "ssdlite" / "weights.pt"
    before = weights.stat().st_mtime_ns
    again = mod.run_unit("std", "ssdlite", tmp_path / "runs", 10.0, tmp_path / "p", 0)
    assert weights.stat().st_mtime_ns == before and again["metrics"] == state["metrics"]
