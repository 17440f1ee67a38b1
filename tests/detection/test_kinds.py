"""Target kinds in the detector: the widened one-class model finds the same boxes, the kind head's inference worked
out by hand (score, kind, share, box of the kind, suppression across kinds), training labels by kind, frozen stages,
kinds through the weights file and the evaluation's class average."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from gpr3d.core.errors import GPR3DError, InvalidDataError  # noqa: E402
from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.detection.data import WindowDataset, kind_labels, random_window  # noqa: E402
from gpr3d.detection.models import build_model, widen_to_kinds  # noqa: E402
from gpr3d.detection.windows import WindowConfig  # noqa: E402

KINDS = ["rebar", "steel_pipe", "pvc_pipe", "void", "tank"]


def _window(seed=0):
    return torch.from_numpy(np.random.default_rng(seed).random((3, 256, 256), dtype=np.float32))


def test_a_widened_detector_finds_what_the_one_class_one_finds():
    one = build_model("frcnn_lean")
    with torch.no_grad():  # a one-class model that finds many boxes: its class bias strongly for 'hyperbola'
        one.roi_heads.box_predictor.cls_score.bias.copy_(torch.tensor([0.0, 2.0]))
    one.eval()
    wide = build_model("frcnn_lean", kinds=KINDS)
    wide.load_state_dict(widen_to_kinds(one.state_dict(), KINDS))
    wide.eval()
    with torch.inference_mode():
        for seed in (0, 1):
            a, b = one([_window(seed)])[0], wide([_window(seed)])[0]
            assert len(a["boxes"]) > 20 and abs(len(a["boxes"]) - len(b["boxes"])) <= 2
            # the 20 best, each paired with the other model's nearest box (rounding may swap near-equal scores
            # on another CPU, so pairs go by place); the sums of five equal shares differ from one share by
            # float32 rounding only: 1e-5
            for j in range(20):
                near = int(torch.argmin((b["boxes"] - a["boxes"][j]).abs().max(dim=1).values))
                torch.testing.assert_close(b["boxes"][near], a["boxes"][j], rtol=0, atol=1e-3)
                torch.testing.assert_close(b["scores"][near], a["scores"][j], rtol=0, atol=1e-5)
            # every kind alike (which wins the tie is rounding's choice), each with a fifth of the score
            torch.testing.assert_close(b["kind_scores"], torch.full_like(b["scores"], 0.2), rtol=0, atol=1e-5)


def test_widening_copies_the_hyperbola_row_lowered_by_log_k():
    sd = build_model("frcnn_lean").state_dict()
    out = widen_to_kinds(sd, ["rebar", "void"])
    w, b = sd["roi_heads.box_predictor.cls_score.weight"], sd["roi_heads.box_predictor.cls_score.bias"]
    ow, ob = out["roi_heads.box_predictor.cls_score.weight"], out["roi_heads.box_predictor.cls_score.bias"]
    assert ow.shape == (3, 512) and torch.equal(ow[0], w[0]) and torch.equal(ow[1], w[1]) and torch.equal(ow[2], w[1])
    assert ob[0] == b[0] and ob[1] == pytest.approx(float(b[1]) - math.log(2)) and ob[2] == ob[1]
    bw = sd["roi_heads.box_predictor.bbox_pred.weight"]
    obw = out["roi_heads.box_predictor.bbox_pred.weight"]
    assert obw.shape == (12, 512) and torch.equal(obw[:4], bw[:4]) and torch.equal(obw[4:8], bw[4:])
    assert torch.equal(obw[8:], bw[4:])
    assert torch.equal(out["roi_heads.box_predictor.bbox_pred.bias"][8:], sd["roi_heads.box_predictor.bbox_pred.bias"][4:])
    assert all(torch.equal(out[k], sd[k]) for k in sd if "box_predictor" not in k)
    with pytest.raises(InvalidDataError) as err:
        widen_to_kinds(out, ["rebar"])
    assert str(err.value) == "only a one-class detector can be widened to kinds (this one has 2)"


class _Pool(torch.nn.Module):
    def forward(self, features, proposals, shapes):
        return torch.cat(proposals)


class _Same(torch.nn.Module):
    def forward(self, x):
        return x


class _Answer(torch.nn.Module):
    """The predictor's stand-in: RoI i gets ``logits[i]`` and ``regression[i]``."""

    def __init__(self, logits, regression):
        super().__init__()
        self.answer = (logits, regression)

    def forward(self, x):
        assert len(x) == len(self.answer[0])
        return self.answer


def _kind_heads(logits, regression, **kw):
    model = build_model("frcnn_lean", kinds=["rebar", "pvc_pipe"])
    heads = model.roi_heads
    heads.box_roi_pool, heads.box_head, heads.box_predictor = _Pool(), _Same(), _Answer(logits, regression)
    for k, v in kw.items():
        setattr(heads, k, v)
    return heads.eval()


def test_kind_head_inference_in_full():
    proposals = [torch.tensor([[10.0, 10, 50, 30], [12, 10, 52, 30], [100, 40, 140, 60], [0, 0, 20, 20]])]
    probs = torch.tensor([[0.1, 0.5, 0.4], [0.2, 0.1, 0.7], [0.6, 0.1, 0.3], [0.995, 0.003, 0.002]])
    reg = torch.zeros(4, 12)
    reg[2, 8] = 1.0  # RoI 2, class 2 (pvc_pipe): dx = 1 / 10 of its 40 px width: 4 px right
    reg[2, 4] = -1.0  # RoI 2, class 1 (rebar): 4 px left; not its kind, so not used
    heads = _kind_heads(probs.log(), reg)
    (r,), _ = heads({}, proposals, [(256, 256)])
    # RoI 0 (score 0.9, rebar 0.5 / 0.9) wins over RoI 1 (0.8), which overlaps it with IoU 38/42 > 0.5
    assert r["scores"].tolist() == pytest.approx([0.9, 0.4], abs=1e-6)
    assert r["labels"].tolist() == [1, 2]
    assert r["kind_scores"].tolist() == pytest.approx([0.5 / 0.9, 0.3 / 0.4], abs=1e-6)
    # every kind's share of the box's score: RoI 0 rebar 0.5 and pipe 0.4 of 0.9, RoI 2 0.1 and 0.3 of 0.4
    torch.testing.assert_close(r["kind_probs"], torch.tensor([[0.5 / 0.9, 0.4 / 0.9], [0.1 / 0.4, 0.3 / 0.4]]),
                               rtol=0, atol=1e-6)
    torch.testing.assert_close(r["boxes"], torch.tensor([[10.0, 10, 50, 30], [104, 40, 144, 60]]), rtol=0, atol=1e-4)
    # boxes are clipped to the image (RoI 2, past its right edge, loses all its width and goes); a lower
    # threshold keeps RoI 3 (score 0.005)
    heads = _kind_heads(probs.log(), reg, score_thresh=0.001)
    (r,), _ = heads({}, [proposals[0] + torch.tensor([200.0, 0, 200, 0])], [(256, 250)])
    torch.testing.assert_close(r["boxes"], torch.tensor([[210.0, 10, 250, 30], [200, 0, 220, 20]]), rtol=0, atol=1e-4)
    assert r["scores"].tolist() == pytest.approx([0.9, 0.005], abs=1e-6)


def test_kind_head_limits_small_boxes_overlap_and_training():
    proposals = [torch.tensor([[10.0, 10, 50, 30], [12, 10, 52, 30], [100, 40, 100.005, 60], [150, 0, 170, 20],
                               [200, 0, 200.5, 20]])]
    probs = torch.tensor([[0.1, 0.5, 0.4], [0.2, 0.1, 0.7], [0.05, 0.5, 0.45], [0.3, 0.6, 0.1], [0.9, 0.05, 0.05]])
    heads = _kind_heads(probs.log(), torch.zeros(5, 12))
    (r,), _ = heads({}, proposals, [(256, 256)])
    # RoI 2 is 0.005 px wide: under the 0.01 px that torchvision's head also drops (RoI 4, 0.5 px, stays);
    # RoI 1 is suppressed by RoI 0
    assert r["scores"].tolist() == pytest.approx([0.9, 0.7, 0.1], abs=1e-6) and r["labels"].tolist() == [1, 1, 1]
    # the shares travel with their boxes through the cuts (RoIs 0, 3 and 4 kept)
    torch.testing.assert_close(r["kind_probs"], torch.tensor([[5 / 9, 4 / 9], [6 / 7, 1 / 7], [0.5, 0.5]]), rtol=0,
                               atol=1e-6)
    # a score equal to the threshold is not above it: at RoI 0's own score nothing is left; just under it, RoI 0
    thresh = float(torch.softmax(probs.log(), -1)[0, 1:].sum())
    (r,), _ = _kind_heads(probs.log(), torch.zeros(5, 12), score_thresh=thresh)({}, proposals, [(256, 256)])
    assert r["scores"].tolist() == []
    (r,), _ = _kind_heads(probs.log(), torch.zeros(5, 12), score_thresh=thresh - 1e-6)({}, proposals, [(256, 256)])
    assert r["scores"].tolist() == pytest.approx([0.9], abs=1e-6)
    proposals[0], probs = proposals[0][:4], probs[:4]
    heads = _kind_heads(probs.log(), torch.zeros(4, 12), nms_thresh=0.95)  # IoU 38 / 42 is kept now
    (r,), _ = heads({}, proposals, [(256, 256)])
    assert r["scores"].tolist() == pytest.approx([0.9, 0.8, 0.7], abs=1e-6) and r["labels"].tolist() == [1, 2, 1]
    heads = _kind_heads(probs.log(), torch.zeros(4, 12), detections_per_img=2)
    (r,), _ = heads({}, proposals, [(256, 256)])
    assert r["scores"].tolist() == pytest.approx([0.9, 0.7], abs=1e-6)
    # two images: each gets its own RoIs' boxes
    heads = _kind_heads(probs.log(), torch.zeros(4, 12))
    (a, b), _ = heads({}, [proposals[0][:2], proposals[0][2:]], [(256, 256), (256, 256)])
    assert a["scores"].tolist() == pytest.approx([0.9], abs=1e-6) and b["scores"].tolist() == pytest.approx([0.7], abs=1e-6)
    torch.testing.assert_close(b["boxes"], proposals[0][3:], rtol=0, atol=1e-4)
    # in training it is torchvision's head: the same losses from the same parts
    from torchvision.models.detection.roi_heads import RoIHeads

    model = build_model("frcnn_lean", kinds=["rebar", "pvc_pipe"]).train()
    images, targets = [_window(3)], [{"boxes": torch.tensor([[40.0, 60, 120, 110]]), "labels": torch.tensor([2])}]
    torch.manual_seed(5)
    losses = model(images, targets)
    model.roi_heads.__class__ = RoIHeads
    torch.manual_seed(5)
    plain = model(images, targets)
    assert set(losses) == set(plain) and all(torch.equal(losses[k], plain[k]) for k in plain)


def test_with_one_kind_the_head_is_torchvision_s():
    from torchvision.models.detection.roi_heads import RoIHeads

    model = build_model("frcnn_lean", kinds=["rebar"]).eval()
    plain = build_model("frcnn_lean").eval()
    plain.load_state_dict(model.state_dict())
    from gpr3d.detection.kindheads import KindRoIHeads

    assert type(plain.roi_heads) is RoIHeads and type(model.roi_heads) is KindRoIHeads
    with torch.inference_mode():
        a, b = plain([_window(3)])[0], model([_window(3)])[0]
    assert torch.equal(a["boxes"], b["boxes"]) and torch.equal(a["labels"], b["labels"])
    torch.testing.assert_close(a["scores"], b["scores"], rtol=0, atol=1e-6)
    assert torch.equal(b["kind_scores"], torch.ones_like(b["scores"]))
    assert torch.equal(b["kind_probs"], torch.ones_like(b["scores"])[:, None])


def test_training_labels_follow_the_kinds():
    assert kind_labels(["pvc_pipe", "rebar", "pvc_pipe"], KINDS).tolist() == [3, 1, 3]
    assert kind_labels(["target", "void"], None).tolist() == [1, 1]  # a one-class network: all hyperbolas
    assert kind_labels([], KINDS).dtype == np.int64
    with pytest.raises(GPR3DError) as err:
        kind_labels(["rebar", "target"], ["rebar", "pvc_pipe"])
    assert str(err.value) == ("a label of kind 'target', which the detector does not name (rebar, pvc_pipe): map the "
                              "dataset's class names onto kinds (--class-kinds NAME=KIND)")


def _record():
    n, dt = 300, 1e-10
    s = Survey(data=np.random.default_rng(0).normal(size=(n, 128)).astype(np.float32), dt_s=dt, frequency_hz=1e9)
    labs = [{"box": [a - 20, 2e-9, a + 20, 5e-9], "apex_trace": a, "apex_time_s": 2.7e-9, "kind": k, "visible": True}
            for a, k in ((60, "void"), (100, "rebar"), (150, "pvc_pipe"), (200, "rebar"))]
    return s, {"labels": labs}


def test_the_window_dataset_labels_each_box_by_its_kind():
    s, labels = _record()
    cfg = WindowConfig(traces=256)
    ds = WindowDataset(lambda i: (s, labels), 6, cfg, seed=1, kinds=KINDS)
    seen = set()
    for i in range(6):
        img, t = ds[i]
        rng = np.random.default_rng(np.random.SeedSequence([1, i, 77]))
        want_img, boxes, kinds = random_window(s, labels, cfg, rng, return_kinds=True)
        np.testing.assert_array_equal(img.numpy(), want_img)
        np.testing.assert_array_equal(t["boxes"].numpy(), boxes)
        assert t["labels"].tolist() == [KINDS.index(k) + 1 for k in kinds]
        # each box is the one of its kind: box centres (flipped or not) put back on the labels' apexes
        seen.update(kinds)
    assert seen == {"void", "rebar", "pvc_pipe"}
    one = WindowDataset(lambda i: (s, labels), 2, cfg, seed=1)
    assert one[0][1]["labels"].tolist() == [1] * len(one[0][1]["boxes"])


def test_frozen_stages_keep_their_weights_fixed():
    from gpr3d.detection.train import _freeze

    model = build_model("frcnn_lean")
    _freeze(model, 2)
    body = model.backbone.body
    fixed = [n for n, p in body.named_parameters() if not p.requires_grad]
    assert fixed and all(n.split(".")[0] in ("conv1", "bn1", "layer1") for n in fixed)
    assert all(p.requires_grad for n, p in body.named_parameters() if n.split(".")[0] not in ("conv1", "bn1", "layer1"))
    assert sum(1 for n in fixed if n.startswith("layer1")) == len(list(body.layer1.parameters()))
    model = build_model("frcnn_lean")
    _freeze(model, 1)
    assert {n.split(".")[0] for n, p in model.backbone.body.named_parameters() if not p.requires_grad} == {"conv1", "bn1"}
    _freeze(model, 0)
    with pytest.raises(GPR3DError) as err:
        _freeze(build_model("ssdlite"), 1)
    assert str(err.value) == "--freeze needs a ResNet backbone (a frcnn_*, retinanet_r18 or fcos_r18 model)"
    model = build_model("frcnn_lean")
    _freeze(model, 4)  # frcnn_lean is cut after layer3: all of its body may be fixed
    assert not any(p.requires_grad for p in model.backbone.body.parameters())
    assert all(p.requires_grad for p in model.backbone.fpn.parameters())


def test_kinds_travel_in_the_weights_file(tmp_path):
    from gpr3d.detection.infer import Detector
    from gpr3d.detection.weights import load_weights, save_weights
    from gpr3d.io.coco import CATEGORIES

    model = build_model("frcnn_lean", kinds=["rebar", "pvc_pipe"])
    save_weights(model, "frcnn_lean", WindowConfig().to_dict(), tmp_path / "w.pt", kinds=["rebar", "pvc_pipe"])
    back, _, _ = load_weights(tmp_path / "w.pt")
    assert back.gpr3d_kinds == ["rebar", "pvc_pipe"] and back.roi_heads.box_predictor.cls_score.out_features == 3
    assert Detector.load(tmp_path / "w.pt").kinds == ["rebar", "pvc_pipe"]
    save_weights(build_model("frcnn_lean"), "frcnn_lean", WindowConfig().to_dict(), tmp_path / "one.pt")
    assert load_weights(tmp_path / "one.pt")[0].gpr3d_kinds is None
    obj = torch.load(tmp_path / "w.pt", weights_only=True)
    obj["kinds"] = "rebar"
    torch.save(obj, tmp_path / "bad.pt")
    from gpr3d.core.errors import FormatError

    with pytest.raises(FormatError) as err:
        load_weights(tmp_path / "bad.pt")
    assert str(err.value) == "bad.pt: kinds must be a list of target kinds, got 'rebar'"
    assert set(CATEGORIES) >= {"rebar", "pvc_pipe"}


def test_evaluation_averages_over_the_kinds_a_detector_names():
    pytest.importorskip("pycocotools")
    from gpr3d.detection.evaluate import coco_metrics, evaluate_detector

    dt = 1e-10
    s = Survey(data=np.zeros((100, 80), np.float32), dt_s=dt, frequency_hz=1e9)
    lab = {"labels": [{"box": [10, 1e-9, 30, 3e-9], "apex_trace": 20, "apex_time_s": 1.1e-9, "kind": "rebar"},
                      {"box": [50, 2e-9, 70, 4e-9], "apex_trace": 60, "apex_time_s": 2.1e-9, "kind": "pvc_pipe"}]}

    class Stub:
        kinds = ["rebar", "pvc_pipe", "void"]

        def detect(self, survey, score_threshold):
            return {"n_windows": 1, "targets": [
                {"box": [10, 1e-9, 30, 3e-9], "score": 0.9, "apex_trace": 20, "apex_time_s": 1.1e-9, "kind": "rebar"},
                {"box": [50, 2e-9, 70, 4e-9], "score": 0.8, "apex_trace": 60, "apex_time_s": 2.1e-9, "kind": "rebar"}]}

    m = evaluate_detector(Stub(), [(s, lab)])
    px = np.array([1, 1 / dt, 1, 1 / dt])
    gt = [np.array([b["box"] for b in lab["labels"]]) * px]
    want = coco_metrics(gt, [gt[0].copy()], [np.array([0.9, 0.8])], gt_kinds=[["rebar", "pvc_pipe"]],
                        det_kinds=[["rebar", "rebar"]], kinds=Stub.kinds)
    assert m["mAP@0.5"] == pytest.approx(1.0)  # class-agnostic: both found
    assert m["by_kind"] == {**want, "kinds": ["pvc_pipe", "rebar"]}
    assert m["by_kind"]["mAP@0.5"] == pytest.approx(0.5)  # the pipe called a rebar: pipe AP 0
    assert m["by_kind_top"] == m["by_kind"]  # no shares: each box stands under its kind alone either way


def test_class_averaged_metrics_score_a_box_under_every_kind_by_its_share():
    pytest.importorskip("pycocotools")
    from gpr3d.detection.evaluate import coco_metrics, evaluate_detector, kind_shares

    dt = 1e-10
    s = Survey(data=np.zeros((100, 80), np.float32), dt_s=dt, frequency_hz=1e9)
    a, b, c, f = [10, 1e-9, 30, 3e-9], [50, 2e-9, 70, 4e-9], [75, 1e-9, 95, 3e-9], [30, 5e-9, 45, 7e-9]
    d = [5, 5e-9, 25, 7e-9]
    lab = {"labels": [{"box": a, "apex_trace": 20, "apex_time_s": 1.1e-9, "kind": "rebar"},
                      {"box": b, "apex_trace": 60, "apex_time_s": 2.1e-9, "kind": "pvc_pipe"},
                      {"box": c, "apex_trace": 85, "apex_time_s": 1.1e-9, "kind": "pvc_pipe"},
                      {"box": d, "apex_trace": 15, "apex_time_s": 5.1e-9, "kind": "pvc_pipe"}]}

    def target(box, score, kind, shares):
        return {"box": box, "score": score, "apex_trace": int(box[0]) + 10, "apex_time_s": box[1] + 1e-10,
                "kind": kind, "kind_shares": dict(zip(["rebar", "pvc_pipe", "void"], shares))}

    class Stub:
        kinds = ["rebar", "pvc_pipe", "void"]

        def detect(self, survey, score_threshold):  # f: a false box, its kind unsure
            return {"n_windows": 1, "targets": [target(f, 0.95, "rebar", [0.6, 0.4, 0.0]),
                                                target(a, 0.9, "rebar", [0.8, 0.2, 0.0]),
                                                target(b, 0.8, "rebar", [0.6, 0.3, 0.1]),
                                                target(c, 0.5, "pvc_pipe", [0.1, 0.9, 0.0]),
                                                target(d, 0.7, "rebar", [1.0, 0.0, 0.0])]}  # no pipe share

    m = evaluate_detector(Stub(), [(s, lab)])
    px = np.array([1, 1 / dt, 1, 1 / dt])
    gt = [np.array([x["box"] for x in lab["labels"]]) * px]
    # every box under the kind it names at its score, and under every other kind of a share above 0 at score x
    # share (no rows for the shares of 0: d is no pipe)
    boxes = np.array([f, f, a, a, b, b, b, c, c, d]) * px
    scores = np.array([0.95, 0.38, 0.9, 0.18, 0.8, 0.24, 0.08, 0.05, 0.5, 0.7])
    kinds = ["rebar", "pvc_pipe", "rebar", "pvc_pipe", "rebar", "pvc_pipe", "void", "rebar", "pvc_pipe", "rebar"]
    want = coco_metrics(gt, [boxes], [scores], gt_kinds=[["rebar", "pvc_pipe", "pvc_pipe", "pvc_pipe"]],
                        det_kinds=[kinds], kinds=Stub.kinds)
    assert m["by_kind"] == {**want, "kinds": ["pvc_pipe", "rebar"]}
    # worked out: rebar: f (0.95, false) above a (0.9): AP 1/2 (at score x share, 0.57 under a's 0.72, it would be
    # 1); pvc_pipe: c (0.5) found, f (0.38) false, b (0.24) found, d never: precision 1 to recall 1/3, 2/3 to 2/3
    # (COCO's 101 recall points: (34 + 33 x 2/3) / 101)
    assert m["by_kind"]["mAP@0.5"] == pytest.approx((0.5 + (34 + 33 * 2 / 3) / 101) / 2, abs=1e-6)
    # recall: rebar 1, pipes 2 of 3; under the named kind alone the pipe b is lost too: 1 of 3
    assert m["by_kind"]["recall@0.5"] == pytest.approx((1 + 2 / 3) / 2)
    assert m["by_kind_top"]["recall@0.5"] == pytest.approx((1 + 1 / 3) / 2)
    assert kind_shares({"kind": "rebar"}) == {"rebar": 1.0} and kind_shares({}) == {"target": 1.0}
    from gpr3d.detection.evaluate import kind_rows

    assert kind_rows({"score": 0.5}) == [("target", 0.5)]  # a one-class detection: its one row
    assert kind_rows({"score": 0.5, "kind": "void", "kind_shares": {"rebar": 0.25, "void": 0.75, "tank": 0.0}}) \
        == [("void", 0.5), ("rebar", 0.125)]
    Stub.kinds = None
    assert "by_kind" not in evaluate_detector(Stub(), [(s, lab)])


def test_a_detector_of_kinds_starts_one_of_some_of_them_with_their_own_rows():
    sd = widen_to_kinds(build_model("frcnn_lean").state_dict(), KINDS)
    torch.manual_seed(1)
    sd = {k: (v + torch.randn_like(v) if "box_predictor" in k else v) for k, v in sd.items()}  # every row its own
    out = widen_to_kinds(sd, ["pvc_pipe", "rebar"], from_kinds=KINDS)
    w, ow = sd["roi_heads.box_predictor.cls_score.weight"], out["roi_heads.box_predictor.cls_score.weight"]
    assert torch.equal(ow, w[[0, 3, 1]])  # background, pvc_pipe, rebar
    assert torch.equal(out["roi_heads.box_predictor.cls_score.bias"], sd["roi_heads.box_predictor.cls_score.bias"][[0, 3, 1]])
    bw = sd["roi_heads.box_predictor.bbox_pred.weight"]
    assert torch.equal(out["roi_heads.box_predictor.bbox_pred.weight"], torch.cat([bw[0:4], bw[12:16], bw[4:8]]))
    bb = sd["roi_heads.box_predictor.bbox_pred.bias"]
    assert torch.equal(out["roi_heads.box_predictor.bbox_pred.bias"], torch.cat([bb[0:4], bb[12:16], bb[4:8]]))
    model = build_model("frcnn_lean", kinds=["pvc_pipe", "rebar"])
    model.load_state_dict(out)  # it fits
    with pytest.raises(InvalidDataError) as err:
        widen_to_kinds(sd, ["rebar", "gravel", "sand"], from_kinds=KINDS)
    assert str(err.value) == "the detector names rebar, steel_pipe, pvc_pipe, void, tank: it cannot start gravel, sand"
    with pytest.raises(InvalidDataError) as err:  # kinds it names, but a head of another size
        widen_to_kinds(sd, ["rebar"], from_kinds=["rebar", "void"])
    assert str(err.value) == "the detector names rebar, void: it cannot start these kinds"


def test_training_from_a_detector_of_kinds_checks_the_kinds_first(tmp_path):
    from gpr3d.detection.train import TrainConfig, train_detector
    from gpr3d.detection.weights import save_weights

    save_weights(build_model("frcnn_lean", kinds=["rebar", "void"]), "frcnn_lean", WindowConfig().to_dict(),
                 tmp_path / "k.pt", kinds=["rebar", "void"])
    cfg = TrainConfig(out=str(tmp_path / "run"), init=str(tmp_path / "k.pt"), kinds=["rebar", "tank"], steps=1, batch=2)
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg, lambda i: None, progress=False, log=lambda *a: None)
    assert str(err.value) == f"--init {tmp_path / 'k.pt'}: names rebar, void; it cannot start tank"
    cfg = TrainConfig(out=str(tmp_path / "run2"), init=str(tmp_path / "k.pt"), steps=1, batch=2,
                      window={**WindowConfig().to_dict(), "overlap": 0.25})
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg, lambda i: None, progress=False, log=lambda *a: None)
    assert str(err.value) == f"--init {tmp_path / 'k.pt'}: made for another model or window; it cannot start 'frcnn_lean'"
