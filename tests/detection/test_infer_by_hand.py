"""``Detector.detect`` and ``load_detector`` by hand: the window, merge and apex helpers replaced by spies with
scripted answers (they are tested on their own), the network by a fake; what detect adds (labels kept, batches,
clipping to the record, the score threshold, the order, which boxes set the width rate, the apex data, the output's
fields) is written out here."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gpr3d.core.errors import GPR3DError, InvalidDataError  # noqa: E402
from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.detection import infer  # noqa: E402
from gpr3d.detection.windows import WindowConfig  # noqa: E402


class _Win:
    def __init__(self, k):
        self.image = np.full((3, 4, 4), float(k), np.float32)
        self.k = k


class _Net:
    """Per window image k: one hyperbola box (label 1) and one box of another label."""

    def __init__(self):
        self.batches, self.mode = [], None

    def eval(self):
        self.mode = "eval"
        return self

    def __call__(self, batch):
        assert not torch.is_grad_enabled()
        self.batches.append([int(im[0, 0, 0]) for im in batch])
        out = []
        for im in batch:
            k = float(im[0, 0, 0])
            out.append({"boxes": torch.tensor([[k, 1.0, k + 2, 3.0], [9.0, 9.0, 10.0, 10.0]]),
                        "scores": torch.tensor([0.1 * (k + 1), 0.99]), "labels": torch.tensor([1, 2])})
        return out


@pytest.fixture
def spies(monkeypatch):
    log = {}

    def prepare(survey, cfg):
        log.setdefault("prepare", []).append(cfg.equalise)
        return np.full((survey.n_traces, 8), 7.0 if cfg.equalise else 3.0, np.float32)

    def equalise_rows(view):
        log.setdefault("equalise", []).append(float(view[0, 0]))
        return np.full_like(view, 7.0)

    def windows(survey, cfg, processed):
        log["windows_processed"] = float(processed[0, 0])
        log["windows_args"] = (survey, cfg)
        return [_Win(k) for k in range(5)]

    def merge(per_window, n_traces, dt_s, nms, return_index=False):
        assert return_index  # detect carries the kinds of the kept boxes by their places
        log["merge"] = ([w.k for w, _, _ in per_window], [b.tolist() for _, b, _ in per_window],
                        [s.tolist() for _, _, s in per_window], n_traces, dt_s, nms)
        boxes = np.array([[-3.0, -1e-9, 10.0, 2e-9],  # clipped at the record's start
                          [20.0, 1e-9, 60.0, 20e-9],  # clipped at its end (49 traces, 9.9 ns)
                          [5.0, 1e-9, 5.0, 2e-9],  # no width: dropped
                          [30.0, 3e-9, 35.0, 4e-9],  # under the threshold: dropped
                          [12.0, 2e-9, 18.0, 5e-9],
                          [40.0, 4e-9, 44.0, 4e-9]])  # no height: dropped
        return boxes, np.array([0.5, 0.95, 0.9, 0.2, 0.45, 0.8]), log.get("merge_index", np.array([0, 1, 2, 3, 4, 0]))

    def rows_interval(survey, cfg):
        log["rows_args"] = (survey, cfg)
        return 2.5e-11

    def width_rate(boxes, n_traces, t_end, f):
        log["width_rate"] = ([list(b) for b in boxes], n_traces, t_end, f)
        return 123.0

    def apex_of_box(data, b, s_per_row, *, frequency_hz, n_traces, width_per_s):
        log.setdefault("apex", []).append((float(data[0, 0]), list(b), s_per_row, frequency_hz, n_traces, width_per_s))
        return b[0] + 1.4, b[1] + 1e-9

    for name, fn in dict(prepare=prepare, equalise_rows=equalise_rows, windows=windows, merge=merge,
                         rows_interval=rows_interval,
                         width_rate=width_rate, apex_of_box=apex_of_box).items():
        monkeypatch.setattr(infer, name, fn)
    return log


def _survey(positions=True, metadata=None):
    n = 50
    pos = np.c_[np.arange(n) * 0.02, np.zeros(n), np.zeros(n)] if positions else None
    return Survey(data=np.zeros((n, 100), np.float32), dt_s=1e-10, positions_xyz=pos, frequency_hz=1e9,
                  metadata={"path": "LINE.DZT", "channel": 2} if metadata is None else metadata)


def test_detect_keeps_clips_thresholds_orders_and_fills_the_contract(spies):
    net = _Net()
    det = infer.Detector(net, WindowConfig(equalise=True), provenance={"name": "test net"}, batch=2)
    det.nms = np.sort  # a stand-in: handed to merge as it is
    survey = _survey()
    out = det.detect(survey, score_threshold=0.45)
    assert spies["windows_args"][0] is survey and spies["windows_args"][1] is det.window
    assert spies["rows_args"][0] is survey and spies["rows_args"][1] is det.window
    assert net.mode == "eval" and net.batches == [[0, 1], [2, 3], [4]]
    ks, boxes, scores, n, dt, nms = spies["merge"]
    assert ks == [0, 1, 2, 3, 4] and (n, dt, nms) == (50, 1e-10, np.sort)
    assert boxes == [[[k, 1.0, k + 2, 3.0]] for k in range(5)]  # label 2 left out
    assert scores == [[pytest.approx(0.1 * (k + 1))] for k in range(5)]
    # the record prepared once, plain; the windows see it equalised, the apexes plain
    assert spies["prepare"] == [False] and spies["equalise"] == [3.0] and spies["windows_processed"] == 7.0
    t_end = (100 - 1) * 1e-10
    # (scores equal to the threshold are kept; a score of 0.5 counts as whole for the width rate)
    want = [([20.0, 1e-9, 49.0, t_end], 0.95), ([0.0, 0.0, 10.0, 2e-9], 0.5), ([12.0, 2e-9, 18.0, 5e-9], 0.45)]
    assert spies["width_rate"] == ([want[0][0], want[1][0]], 50, t_end, 1e9)  # the boxes scoring 0.5 or more
    assert [a[1] for a in spies["apex"]] == [w[0] for w in want]
    assert all(a[0] == 3.0 and a[2:] == (2.5e-11, 1e9, 50, 123.0) for a in spies["apex"])
    assert [t["box"] for t in out["targets"]] == [w[0] for w in want]
    assert [t["score"] for t in out["targets"]] == [0.95, 0.5, 0.45]
    assert [t["apex_trace"] for t in out["targets"]] == [21, 1, 13]  # rounded from 21.4, 1.4, 13.4
    assert [t["apex_time_s"] for t in out["targets"]] == pytest.approx([2e-9, 1e-9, 3e-9], rel=1e-12)
    assert [t["x_m"] for t in out["targets"]] == pytest.approx([0.428, 0.028, 0.268], rel=1e-12)
    assert (out["input"], out["channel"], out["n_traces"], out["dt_s"], out["n_windows"]) == \
        ("LINE.DZT", 2, 50, 1e-10, 5)
    assert (out["detector"], out["score_threshold"]) == ("test net", 0.45) and 0 <= out["wall_s"] < 5
    # a one-class network names no kind
    assert [(t["kind"], t["kind_score"]) for t in out["targets"]] == [("target", None)] * 3


class _KindNet(_Net):
    """Per window image k: boxes of labels 1..3 (kinds) and 4 (past the kinds: dropped), with kind shares."""

    gpr3d_kinds = ["rebar", "pvc_pipe", "void"]

    def __call__(self, batch):
        out = []
        for im in batch:
            k = float(im[0, 0, 0])
            out.append({"boxes": torch.tensor([[k, 1.0, k + 2, 3.0], [9.0, 9.0, 10.0, 10.0]]),
                        "scores": torch.tensor([0.1 * (k + 1), 0.99]),
                        "labels": torch.tensor([int(k) % 3 + 1, 4]),
                        "kind_scores": torch.tensor([0.5 + 0.1 * k, 1.0])})
        return out


def test_detect_names_its_stages_for_whoever_times_them(spies):
    from gpr3d.core.timing import collect

    det = infer.Detector(_Net(), WindowConfig(equalise=True))
    with collect(compile_times=False) as t:
        det.detect(_survey(), score_threshold=0.45)
    assert list(t.seconds) == ["prepare", "windows", "network", "merge", "apexes"] and set(t.counts.values()) == {1}


def test_detect_names_each_kept_box_by_its_place_in_the_windows(spies):
    det = infer.Detector(_KindNet(), WindowConfig(equalise=False))
    assert det.kinds == ["rebar", "pvc_pipe", "void"]
    spies["merge_index"] = np.array([4, 1, 0, 2, 3, 3])  # the merged boxes came from these window boxes
    out = det.detect(_survey(), score_threshold=0.45)
    _, boxes, scores, *_ = spies["merge"]
    assert boxes == [[[k, 1.0, k + 2, 3.0]] for k in range(5)]  # label 4 left out
    # kept in score order: merged boxes 1 (from window box 1), 0 (from 4), 4 (from 3)
    assert [t["score"] for t in out["targets"]] == [0.95, 0.5, 0.45]
    assert [t["kind"] for t in out["targets"]] == ["pvc_pipe", "pvc_pipe", "rebar"]
    assert [t["kind_score"] for t in out["targets"]] == pytest.approx([0.6, 0.9, 0.8])
    # a network that gives no other kinds' shares (an ONNX graph exported before them): the best kind's alone
    assert [t["kind_shares"] for t in out["targets"]] == [{"rebar": 0.0, "pvc_pipe": 0.6, "void": 0.0},
                                                          {"rebar": 0.0, "pvc_pipe": 0.9, "void": 0.0},
                                                          {"rebar": 0.8, "pvc_pipe": 0.0, "void": 0.0}]


class _KindProbsNet(_KindNet):
    """:class:`_KindNet` with every kind's share: window k's box gives kind (k + 1) % 3 the rest."""

    def __call__(self, batch):
        out = super().__call__(batch)
        for im, r in zip(batch, out):
            k = int(im[0, 0, 0])
            probs = torch.zeros(2, 3)
            probs[0, k % 3] = 0.5 + 0.1 * k + 4e-5  # (kept to 4 places: 0.6 from 0.60004)
            probs[0, (k + 1) % 3] = 0.5 - 0.1 * k - 4e-5
            probs[1, 0] = 1.0
            r["kind_probs"] = probs
        return out


def test_detect_gives_every_kind_s_share_of_each_kept_box(spies):
    det = infer.Detector(_KindProbsNet(), WindowConfig(equalise=False))
    spies["merge_index"] = np.array([4, 1, 0, 2, 3, 3])
    out = det.detect(_survey(), score_threshold=0.45)
    # kept: the boxes of windows 1 (pvc_pipe 0.6, void 0.4), 4 (pvc_pipe 0.9, void 0.1) and 3 (rebar 0.8,
    # pvc_pipe 0.2), as the merge index places them
    assert [t["kind_shares"] for t in out["targets"]] == [{"rebar": 0.0, "pvc_pipe": 0.6, "void": 0.4},
                                                          {"rebar": 0.0, "pvc_pipe": 0.9, "void": 0.1},
                                                          {"rebar": 0.8, "pvc_pipe": 0.2, "void": 0.0}]
    assert [t["kind"] for t in out["targets"]] == ["pvc_pipe", "pvc_pipe", "rebar"]
    # a one-class network's targets have none
    assert all("kind_shares" not in t for t in infer.Detector(_Net(), WindowConfig(equalise=False))
               .detect(_survey(), score_threshold=0.45)["targets"])

    class FourItems(infer.Detector):  # a detector of the caller's own that gives no other kinds' shares
        def predict_windows_kinds(self, images):
            return [r[:4] for r in super().predict_windows_kinds(images)]

    four = FourItems(_KindProbsNet(), WindowConfig(equalise=False)).detect(_survey(), score_threshold=0.45)
    assert [t["kind"] for t in four["targets"]] == ["pvc_pipe", "pvc_pipe", "rebar"]
    assert [t["kind_shares"] for t in four["targets"]] == [{"rebar": 0.0, "pvc_pipe": 0.6, "void": 0.0},
                                                           {"rebar": 0.0, "pvc_pipe": 0.9, "void": 0.0},
                                                           {"rebar": 0.8, "pvc_pipe": 0.0, "void": 0.0}]


def test_detect_without_positions_equalising_or_a_name(spies):
    det = infer.Detector(_Net(), WindowConfig(equalise=False))
    out = det.detect(_survey(positions=False, metadata={}), input_name="given.h5")
    assert spies["prepare"] == [False] and "equalise" not in spies  # one view serves both
    assert [t["score"] for t in out["targets"]] == [0.95, 0.5]  # the default threshold: 0.5
    assert out["channel"] == 0
    assert len(det.detect(_survey(), score_threshold=0.0)["targets"]) == 4  # the ends of 0..1 are allowed
    assert [t["score"] for t in det.detect(_survey(), score_threshold=1.0)["targets"]] == []
    assert all("x_m" not in t for t in out["targets"])
    assert (out["input"], out["detector"], out["score_threshold"]) == ("given.h5", "gpr3d detector", 0.5)
    assert det.batch == 8 and det.provenance == {} and det.device == "cpu"


@pytest.mark.parametrize("bad", [-0.01, 1.01, float("nan")])
def test_a_wrong_threshold_is_named_before_any_work(spies, bad):
    with pytest.raises(InvalidDataError) as err:
        infer.Detector(_Net(), WindowConfig()).detect(_survey(), score_threshold=bad)
    assert str(err.value) == f"score threshold must lie in 0..1, got {bad!r}"
    assert "prepare" not in spies


def test_the_engine_is_chosen_by_the_file_the_device_and_what_is_installed(monkeypatch, tmp_path):
    from gpr3d.detection import ort

    from types import SimpleNamespace

    from gpr3d.detection import refine

    calls, refiners = [], []

    def loaded(engine):
        def load(cls, p, device):
            calls.append((engine, p, device))
            return SimpleNamespace(model=None if engine == "onnx" else object(), refiner=None)
        return classmethod(load)

    monkeypatch.setattr(ort.OnnxDetector, "load", loaded("onnx"))
    monkeypatch.setattr(infer.Detector, "load", loaded("torch"))
    monkeypatch.setattr(refine, "load_refiner", lambda p, engine, mirror, passes, rule, quality_weight, fine:
                        refiners.append((p, engine)) or (p, engine, mirror, passes) +
                        (() if (rule, quality_weight) == ("auto", refine.QUALITY_WEIGHT) else (rule, quality_weight)) +
                        (() if fine == "auto" else (fine,)))
    shipped = tmp_path / "default.onnx"
    monkeypatch.setattr(ort, "DEFAULT_ONNX", shipped)
    import importlib.util

    have = {"onnxruntime": True}
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: object() if have.get(name) else None)
    infer.load_detector()  # no shipped export: torch
    shipped.write_bytes(b"x")
    infer.load_detector()  # shipped export, runtime installed, CPU: onnx
    infer.load_detector(device="cuda")  # a GPU: torch
    have["onnxruntime"] = False
    infer.load_detector()  # runtime missing: torch
    infer.load_detector("m.ONNX")  # an export: onnx, whatever is installed
    infer.load_detector("m.pt", engine="torch")
    infer.load_detector("m.pt")  # a weights file: torch
    infer.load_detector(engine="onnx")  # the shipped export
    infer.load_detector(engine="int8")  # the shipped export's 8-bit graph
    assert calls == [("torch", None, "cpu"), ("onnx", None, "cpu"), ("torch", None, "cuda"), ("torch", None, "cpu"),
                     ("onnx", "m.ONNX", "cpu"), ("torch", "m.pt", "cpu"), ("torch", "m.pt", "cpu"),
                     ("onnx", None, "cpu"), ("onnx", ort.DEFAULT_INT8, "cpu")]
    # the shipped refiner with the shipped detector only, in the detector's engine
    assert refiners == [(None, "torch"), (None, "onnx"), (None, "torch"), (None, "torch"), (None, "onnx"),
                        (None, "onnx")]
    assert infer.load_detector(refiner="none").refiner is None and infer.load_detector(refiner=None).refiner is None
    assert infer.load_detector("m.pt", refiner="r.pt").refiner == ("r.pt", "torch", True, 2)  # the shipped way
    assert infer.load_detector("m.onnx", refiner="default", refine_passes=3).refiner == (None, "onnx", True, 3)
    assert infer.load_detector(refine_mirror=False).refiner == (None, "torch", False, 2)
    assert infer.load_detector(box_rule="pgpr", quality_weight=0).refiner == (None, "torch", True, 2, "pgpr", 0.0)
    # the fine stage as asked (auto: the refiner's loader picks the shipped one for the shipped refiner)
    assert infer.load_detector(fine_refiner="none").refiner == (None, "torch", True, 2, "none")
    assert infer.load_detector("m.pt", refiner="r.pt", fine_refiner="f.pt").refiner == ("r.pt", "torch", True, 2, "f.pt")
    for kw, msg in [(dict(engine="tensorrt"), "unknown engine 'tensorrt'; choose one of auto, torch, onnx, int8"),
                    (dict(path="m.pt", engine="onnx"), "--runtime onnx needs an .onnx file (export one with python "
                     "references/detection/export_onnx.py m.pt OUT.onnx), not m.pt"),
                    (dict(path="m.onnx", engine="torch"), "m.onnx is an ONNX export: run it with --runtime onnx (or auto)"),
                    (dict(path="m.pt", engine="int8"), "--runtime int8 runs the shipped detector's 8-bit graph; for m.pt "
                     "make one with python references/detection/quantize_onnx.py OUT.onnx and run it with --runtime "
                     "onnx")]:
        with pytest.raises(GPR3DError) as err:
            infer.load_detector(**kw)
        assert str(err.value) == msg


def test_the_fastest_engine_is_the_8bit_graph_for_the_shipped_model_on_the_cpu_where_it_can_run(monkeypatch,
                                                                                                  tmp_path):
    import importlib.util

    from gpr3d.detection import ort

    graph = tmp_path / "int8.onnx"
    monkeypatch.setattr(ort, "DEFAULT_INT8", graph)
    have = {"onnxruntime": True}
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: object() if have.get(name) else None)
    assert infer.fastest_engine() == "auto"  # no 8-bit graph installed
    graph.write_bytes(b"x")
    assert infer.fastest_engine() == infer.fastest_engine(None, "cpu") == "int8"
    assert infer.fastest_engine("m.pt") == "auto" and infer.fastest_engine("m.onnx") == "auto"  # the user's own
    assert infer.fastest_engine(None, "cuda") == infer.fastest_engine(None, "cuda:1") == "auto"  # a GPU: torch
    have["onnxruntime"] = False
    assert infer.fastest_engine() == "auto"  # no ONNX Runtime


def test_the_shipped_weights_load_into_a_detector_and_its_windows_give_float64_boxes():
    from gpr3d.detection.weights import load_weights

    det = infer.Detector.load()
    model, window, prov = load_weights()
    assert det.window == window and det.provenance == prov and det.device == "cpu" and det.batch == 8
    assert isinstance(det.model, torch.nn.Module) and not det.model.training
    sd, ref = det.model.state_dict(), model.state_dict()
    assert all(torch.equal(sd[k], ref[k]) for k in ref)
    out = det.predict_windows([np.random.default_rng(0).random((3, window.rows, window.traces), dtype=np.float32)])
    assert len(out) == 1 and out[0][0].dtype == np.float64 and out[0][1].dtype == np.float64


class _BrightNet(_Net):
    """A box 6 image columns wide around the centre of each window's bright columns, rows 2..10;
    the score says how many times the record was stretched (0.5 + factor / 10: which view it came from)."""

    factor = 1.0

    def __call__(self, batch):
        out = []
        for im in batch:
            m = np.abs(im[0].numpy() - im[0, 0, 0].item()).max(axis=0)  # against the picture's zero
            c = float(np.sum(np.arange(m.size) * m) / np.sum(m)) + 0.5  # the bright columns' centre, in pixels
            left = 0.01 if c < 60 else 0.0  # the bright trace in the left part: only the unmirrored x1 view
            out.append({"boxes": torch.tensor([[c - 3.0, 2.0, c + 3.0, 10.0]]),
                        "scores": torch.tensor([0.5 + self.factor / 10 + left]), "labels": torch.tensor([1])})
        return out


_PLAIN = WindowConfig(dewow=False, background=False, equalise=False)  # the one bright trace stays alone


def _one_bright_trace(n=80, at=37):
    data = np.zeros((n, 100), np.float32)
    data[at, 40:46] = [1, -2, 3, -3, 2, -1]
    return Survey(data=data, dt_s=1e-10, frequency_hz=1e9)


@pytest.mark.parametrize("factor, mirror, half", [(1.0, False, 3.0), (2.0, False, 1.5), (3.0, False, 1.0),
                                                  (1.0, True, 3.0), (2.0, True, 1.5), (0.5, False, 6.0)])
def test_a_view_s_boxes_come_back_to_the_record_s_traces(factor, mirror, half):
    net = _BrightNet()
    net.factor = factor
    det = infer.Detector(net, _PLAIN)
    survey = _one_bright_trace()
    ((boxes, scores, labels, shares, probs),), n_windows, proc = det._view(survey, None, factor, mirror)
    # the bright trace 37 is seen at column 37 f (mirrored: (79 - 37) f), the box's 6 columns are 6 / f traces
    left = 0.01 if (42 if mirror else 37) * factor < 60 else 0.0  # where the fake network saw the bright trace
    assert n_windows == 1 and labels.tolist() == [1] and scores.tolist() == [pytest.approx(0.5 + factor / 10 + left)]
    s_per_row = (100 - 1) * 1e-10 / (256 - 1)
    assert boxes[0] == pytest.approx([37 - half, 1.5 * s_per_row, 37 + half, 9.5 * s_per_row], abs=1e-9)
    assert proc.shape == (80, 256)


def test_the_views_are_fused_into_the_record_s_boxes():
    class Net(_BrightNet):
        def __call__(self, batch):  # the stretch read back from the bright trace's width: 1 column, or 3 at x2
            m = np.abs(batch[0][0].numpy() - batch[0][0, 0, 0].item()).max(axis=0)
            self.factor = 2.0 if np.sum(m > 0.01 * m.max()) == 3 else 1.0
            return super().__call__(batch)

    det = infer.Detector(Net(), _PLAIN)
    det.trace_scales, det.mirror = (1.0, 2.0), True
    survey = _one_bright_trace(n=120, at=37)
    out = det.detect(survey, score_threshold=0.0)
    (t,) = out["targets"]  # four views, one hyperbola: IoU of [34, 40] and [35.5, 38.5] is 0.5
    assert out["n_windows"] == 4
    # corners the score-weighted mean of the four views': x1 at 0.61 (unmirrored) and 0.6 (mirrored) ([34, 40]),
    # x2 both at 0.7 ([35.5, 38.5]) (the network's scores are float32: to 3e-8)
    assert t["box"][0] == pytest.approx((1.21 * 34 + 2 * 0.7 * 35.5) / 2.61, abs=1e-6)
    assert t["box"][2] == pytest.approx((1.21 * 40 + 2 * 0.7 * 38.5) / 2.61, abs=1e-6)
    assert t["score"] == pytest.approx(0.7)
    assert out["views"] == {"trace_scales": [1.0, 2.0], "mirror": True}
    det.fuse_average = False  # the best view's corners
    assert det.detect(survey, score_threshold=0.0)["targets"][0]["box"][0::2] == pytest.approx([35.5, 38.5])
    det.vote = True  # the score: the four views' summed over four
    assert det.detect(survey, score_threshold=0.0)["targets"][0]["score"] == pytest.approx(2.61 / 4)
    det.mirror, det.vote, det.fuse_average = False, False, True  # two views, unmirrored: x1's box scores 0.61
    out = det.detect(survey, score_threshold=0.0)
    assert out["n_windows"] == 2 and out["views"] == {"trace_scales": [1.0, 2.0], "mirror": False}
    assert out["targets"][0]["box"][0] == pytest.approx((0.61 * 34 + 0.7 * 35.5) / 1.31, abs=1e-6)


class _ShiftedNet(_BrightNet):
    """The bright trace's box moved ``shift`` columns right, scored ``score``: another member of an ensemble."""

    def __init__(self, shift, score):
        self.shift, self.score = shift, score

    def __call__(self, batch):
        out = super().__call__(batch)
        for r in out:
            r["boxes"] = r["boxes"] + torch.tensor([self.shift, 0.0, self.shift, 0.0])
            r["scores"] = torch.tensor([self.score])
        return out


def test_an_ensemble_fuses_each_member_network_s_boxes_as_views():
    det = infer.Detector(_ShiftedNet(0.0, 0.8), _PLAIN)
    survey = _one_bright_trace()
    alone = det.detect(survey, score_threshold=0.0)
    assert [t["box"][0] for t in alone["targets"]] == pytest.approx([34.0])
    det.set_members([infer.Detector(_ShiftedNet(1.0, 0.4), _PLAIN, provenance={"name": "twin"})])  # [35, 41]: IoU
    # 5/7 with [34, 40], one group
    out = det.detect(survey, score_threshold=0.0)
    (t,) = out["targets"]
    assert out["n_windows"] == 1  # the windows are cut once; each network reads them
    assert alone["members"] == [] and out["members"] == ["twin"]
    assert t["box"][0] == pytest.approx((0.8 * 34 + 0.4 * 35) / 1.2, abs=1e-6)  # corners weighted by score
    assert t["box"][2] == pytest.approx((0.8 * 40 + 0.4 * 41) / 1.2, abs=1e-6)
    assert t["score"] == pytest.approx(0.8)  # the best member's score
    det.vote = True  # the score: the group's mean over the two networks
    assert det.detect(survey, score_threshold=0.0)["targets"][0]["score"] == pytest.approx(0.6)
    det.set_members([infer.Detector(_ShiftedNet(5.0, 0.4), _PLAIN)])  # [39, 45]: no overlap to speak of, two boxes
    boxes = sorted(t["box"][0] for t in det.detect(survey, score_threshold=0.0)["targets"])
    assert boxes == pytest.approx([34.0, 39.0]) and det.members[0].model.shift == 5.0
    det.set_members([infer.Detector(_ShiftedNet(1.0, 0.4), _PLAIN)])  # an unnamed member: named as the detector is
    assert det.detect(survey, score_threshold=0.0)["members"] == ["gpr3d detector"]
    det.set_members([])  # no member: the detector alone again
    assert det.detect(survey, score_threshold=0.0)["targets"][0]["box"] == pytest.approx(alone["targets"][0]["box"])


def test_an_ensemble_member_must_read_the_same_windows_and_name_the_same_kinds():
    det = infer.Detector(_ShiftedNet(0.0, 0.8), _PLAIN)
    with pytest.raises(InvalidDataError, match=r"member 1 \(wide\): its windows"):
        det.set_members([infer.Detector(_ShiftedNet(0.0, 0.8), WindowConfig(), provenance={"name": "wide"})])
    other = infer.Detector(_ShiftedNet(0.0, 0.8), _PLAIN, provenance={"name": "kinds2"})
    other.model.gpr3d_kinds = ["rebar", "pvc_pipe"]
    with pytest.raises(InvalidDataError, match=r"member 2 \(kinds2\): it names the kinds \['rebar', 'pvc_pipe'\]"):
        det.set_members([infer.Detector(_ShiftedNet(0.0, 0.8), _PLAIN), other])
    with pytest.raises(InvalidDataError, match=r"member 1 \(gpr3d detector\): its windows"):  # unnamed
        det.set_members([infer.Detector(_ShiftedNet(0.0, 0.8), WindowConfig())])
    with pytest.raises(InvalidDataError, match=r"member 1 \(gpr3d detector\): it names"):
        other.provenance = {}
        det.set_members([other])
    with pytest.raises(InvalidDataError, match=r"member 1: not a detector \(str\)"):
        det.set_members(["weights.pt"])
    assert det.members == ()  # nothing set by a refused call


def test_the_auto_trace_scale_stretches_a_record_to_the_training_records_width():
    from gpr3d.detection.windows import prepare, trace_width

    net = _BrightNet()
    det = infer.Detector(net, _PLAIN)
    survey = _one_bright_trace()
    proc = prepare(survey, _PLAIN)
    w = trace_width(proc)
    det.reference_width = 2.0 * w
    assert det.auto_scale(proc) == pytest.approx(2.0, rel=1e-12)
    auto = det._view(survey, None, "auto", False)
    two = det._view(survey, None, 2.0, False)
    assert np.array_equal(auto[0][0][0], two[0][0][0]) and auto[1] == two[1] == 1
    det.trace_scales = ("auto",)  # through detect: the view named as asked, the boxes the x2 view's
    out = det.detect(survey, score_threshold=0.0)
    assert out["views"] == {"trace_scales": ["auto"], "mirror": False}
    assert out["targets"][0]["box"] == pytest.approx(two[0][0][0][0].tolist(), abs=1e-12)
    det.reference_width = 100 * w  # kept within 0.25..4
    assert det.auto_scale(proc) == 4.0
    det.reference_width = 0.01 * w
    assert det.auto_scale(proc) == 0.25
    # the width comes with weights that recorded it (finetune_pgpr.py), none otherwise
    assert infer.Detector(net, _PLAIN, provenance={"trace_width": 12.5}).reference_width == 12.5
    assert infer.Detector(net, _PLAIN, provenance={"name": "x"}).reference_width is None
    det.trace_scales, det.reference_width = ("auto",), None
    with pytest.raises(InvalidDataError, match="^trace scale 'auto' needs the width of the detector's training "):
        det.detect(survey)


def test_a_calibrated_detector_thresholds_and_reports_calibrated_scores(spies):
    # a = 2, b = 0: s -> s^2 / (s^2 + (1 - s)^2); by hand: 0.95 -> 0.9025 / 0.905, 0.45 -> 0.2025 / 0.505
    cal = {"method": "platt", "a": 2.0, "b": 0.0}
    det = infer.Detector(_Net(), WindowConfig(equalise=True), provenance={"score_calibration": cal})
    assert det.calibration == cal
    out = det.detect(_survey(), score_threshold=0.45)
    # 0.45 calibrates to 0.401, under the threshold: only the boxes raw 0.95 and 0.5 (which stays 0.5) are kept
    assert [t["score"] for t in out["targets"]] == pytest.approx([0.9025 / 0.905, 0.5], abs=1e-12)
    assert [t["box"][0] for t in out["targets"]] == [20.0, 0.0] and out["calibrated"] is True
    plain = infer.Detector(_Net(), WindowConfig(equalise=True)).detect(_survey(), score_threshold=0.45)
    assert plain["calibrated"] is False and len(plain["targets"]) == 3


@pytest.mark.parametrize("bad", [{"method": "isotonic"}, {"method": "platt", "a": 0.0, "b": 1.0},
                                 {"method": "platt", "a": 1.0, "b": float("nan")}, [1, 2]])
def test_a_bad_score_calibration_in_the_weights_is_one_line(bad):
    with pytest.raises(GPR3DError, match="^net x: score_calibration: "):
        infer.Detector(_Net(), WindowConfig(), provenance={"name": "net x", "score_calibration": bad})


def test_a_bad_score_calibration_of_unnamed_weights_names_the_detector():
    with pytest.raises(GPR3DError, match=r"^detector: score_calibration: a must be"):
        infer.Detector(_Net(), WindowConfig(), provenance={"score_calibration": {"method": "platt", "a": -1, "b": 0}})
