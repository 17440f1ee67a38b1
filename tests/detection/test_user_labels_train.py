"""Fine-tuning on the user's own labels: `gpr3d train detector --init default --labels ...`."""

import hashlib
import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from tests.cli.test_cli import run_cli  # noqa: E402
from tests.io.test_userlabels import _write_coco  # noqa: E402


@pytest.fixture(scope="module")
def user_set(tmp_path_factory):
    from gpr3d.simulation.surveys import survey_sample

    d = tmp_path_factory.mktemp("user")
    return _write_coco(d, [survey_sample(4321, i) for i in (0, 1)], height=256)


def test_fine_tuning_on_user_labels_changes_the_weights_and_records_them(tmp_path, user_set):
    from gpr3d.detection.weights import load_weights

    out = tmp_path / "ft"
    r = run_cli("train", "detector", "--init", "default", "--labels", user_set, "--labels-fraction", "1",
                "--steps", "2", "--batch", "2", "--warmup", "1", "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "2 labelled record(s)" in r.stdout
    new, _, prov = load_weights(out / "weights.pt")
    old, _, _ = load_weights()
    diff = max(float((a - b).abs().max()) for a, b in zip(new.state_dict().values(), old.state_dict().values())
               if a.is_floating_point())
    assert diff > 1e-4  # it trained from the shipped weights ...
    first = next(iter(old.state_dict().values()))
    assert first.shape == next(iter(new.state_dict().values())).shape
    assert prov["config"]["init"].endswith("default_detector.pt")
    assert prov["labels_sha256"] == {user_set.name: hashlib.sha256(user_set.read_bytes()).hexdigest()}


def test_user_windows_carry_the_user_boxes(user_set):
    """With --labels-fraction 1 every window comes from the user's records, boxes where the labels put them."""
    from gpr3d.detection.data import MixedSource, RecordsSource, WindowDataset
    from gpr3d.detection.windows import WindowConfig
    from gpr3d.io.userlabels import read_user_labels

    recs = read_user_labels(user_set)

    def never(i):
        raise AssertionError("the synthetic source was drawn")

    ds = WindowDataset(MixedSource(never, RecordsSource(recs), 1.0), 6, WindowConfig(), seed=3, flip=False)
    seen = 0
    for i in range(6):
        image, target = ds[i]
        assert image.shape == (3, 256, 256)
        seen += len(target["boxes"])
    assert seen > 0
    # the labels of record 0 land on its window's pixels as the pixel map says
    from gpr3d.detection.windows import make_window, prepare, record_scale, rows_interval, window_targets

    s, lab = recs[0]
    cfg = WindowConfig()
    proc = prepare(s, cfg)
    win = make_window(proc, 0, cfg, rows_interval(s, cfg), record_scale(proc))
    boxes = window_targets(lab["labels"], win)
    inside = [x for x in lab["labels"] if 0 <= x["apex_trace"] <= cfg.traces and x["box"][2] <= cfg.traces]
    assert len(boxes) >= len(inside) > 0
    for x in inside:
        px = win.pixmap.box_to_px(x["box"])
        assert any(np.allclose(b, px, atol=1e-3) for b in boxes)


@pytest.mark.parametrize("args, msg", [
    (["--labels", "{missing}"], "no such file"),
    (["--labels", "{user}", "--labels-fraction", "1.5"], "--labels-fraction must lie in 0..1"),
    (["--labels", "{user}", "--pixel-map", "t0_s=0"], "needs s_per_px"),
    (["--packed", "{missing}"], "no such file"),
])
def test_fine_tuning_bad_arguments_one_line(tmp_path, user_set, args, msg):
    args = [a.format(missing=tmp_path / "none.json", user=user_set) for a in args]
    r = run_cli("train", "detector", "--out", tmp_path / "x", "--steps", "1", "--batch", "2", *args)
    assert r.returncode != 0
    assert msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "x" / "checkpoint.pt").exists()


def test_fine_tuning_on_a_yolo_set_with_kinds_names_them_in_the_weights_and_in_detect(tmp_path):
    """A one-class start widened to two kinds, trained on YOLO pictures; the weights and their detections name
    the kinds (each detection one of them, its share a probability)."""
    from gpr3d.detection.weights import load_weights
    from tests.cli.test_labels_cli import PM, _yolo

    root = _yolo(tmp_path / "ds")
    out = tmp_path / "ft"
    r = run_cli("train", "detector", "--init", "default", "--kinds", "rebar,pvc_pipe", "--labels", root,
                "--class-names", "steel,pipe", "--class-kinds", "pipe=pvc_pipe", "--pixel-map", PM,
                "--labels-fraction", "1", "--freeze", "2", "--steps", "2", "--batch", "2", "--warmup", "1",
                "--augment", "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    model, _, prov = load_weights(out / "weights.pt")
    assert model.gpr3d_kinds == ["rebar", "pvc_pipe"] and prov["config"]["freeze"] == 2
    assert prov["config"]["augment"] == {"stretch": [0.7, 1.4], "gain": [0.6, 1.8], "noise": 0.15}
    old, _, _ = load_weights()
    # the frozen stem did not move; the widened head did
    assert torch.equal(model.backbone.body.conv1.weight, old.backbone.body.conv1.weight)
    assert model.roi_heads.box_predictor.cls_score.out_features == 3
    d = tmp_path / "d.json"
    r = run_cli("detect", root / "images" / "b0.png", "--pixel-map", PM, "--weights", out / "weights.pt",
                "--score", "0", "--depth", "none", "--out", d)
    assert r.returncode == 0, r.stderr
    targets = json.loads(d.read_text())["targets"]
    assert targets and all(t["kind"] in ("rebar", "pvc_pipe") and 0.5 <= t["kind_score"] <= 1 for t in targets)


def test_coco_category_names_map_onto_kinds(tmp_path, user_set):
    from gpr3d.io.labelled import read_labelled

    recs = read_labelled(user_set)
    names = {lab["source_name"] for _, r in recs for lab in r["labels"]}
    first = sorted(names)[0]
    mapped = read_labelled(user_set, kinds=f"{first}=tank")
    for (_, a), (_, b) in zip(recs, mapped):
        for la, lb in zip(a["labels"], b["labels"]):
            assert lb["kind"] == ("tank" if la["source_name"] == first else la["kind"])
            assert lb["category"] == (5 if la["source_name"] == first else la["category"])
