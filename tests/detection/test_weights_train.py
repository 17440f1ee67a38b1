"""Weight files (round trip, bad files, the shipped default) and resumable training."""

import json

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from gpr3d.core.errors import FormatError, GPR3DError  # noqa: E402
from gpr3d.detection.infer import Detector, load_detector  # noqa: E402
from gpr3d.detection.models import build_model  # noqa: E402
from gpr3d.detection.train import TrainConfig, train_detector  # noqa: E402
from gpr3d.detection.weights import DEFAULT_WEIGHTS, load_weights, save_weights  # noqa: E402
from gpr3d.detection.windows import WindowConfig  # noqa: E402
from gpr3d.simulation.surveys import survey_sample  # noqa: E402


def test_round_trip_gives_the_same_detections(tmp_path):
    m = build_model("ssdlite").eval()
    save_weights(m, "ssdlite", WindowConfig().to_dict(), tmp_path / "w.pt", provenance={"name": "x"})
    m2, win, prov = load_weights(tmp_path / "w.pt")
    x = [torch.rand(3, 256, 256, generator=torch.Generator().manual_seed(1))]
    with torch.inference_mode():
        a, b = m(x)[0]["scores"][:5], m2(x)[0]["scores"][:5]
    assert prov == {"name": "x"} and win == WindowConfig()
    assert torch.allclose(a, b, atol=2e-2)  # float16 storage


def test_bad_weight_files_give_one_line(tmp_path):
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(FormatError, match="not a readable weights file"):
        load_weights(tmp_path / "junk.pt")
    torch.save({"hello": 1}, tmp_path / "other.pt")
    with pytest.raises(FormatError, match="not a gpr3d detector"):
        load_weights(tmp_path / "other.pt")
    m = build_model("ssdlite")
    save_weights(m, "frcnn_lean", WindowConfig().to_dict(), tmp_path / "mismatch.pt")
    with pytest.raises(FormatError, match="do not fit model 'frcnn_lean'"):
        load_weights(tmp_path / "mismatch.pt")
    with pytest.raises(FormatError, match="no such detector weights file"):
        load_weights(tmp_path / "absent.pt")


def test_default_weights_reach_their_recorded_metrics():
    prov = json.loads(DEFAULT_WEIGHTS.with_suffix(".json").read_text())
    check = prov["check"]
    from gpr3d.detection.evaluate import evaluate_detector

    det = Detector.load()
    recs = [survey_sample(check["seed"], i) for i in range(check["n"])]
    m = evaluate_detector(det, recs, score_threshold=0.5)
    for k in ("mAP@0.5", "mAP@0.75", "apex_recall"):
        assert m[k] == pytest.approx(check["metrics"][k], abs=0.03), k
    assert m["mAP@0.5"] > 0.5  # and they are those of a working detector


def test_training_checkpoints_and_resumes(tmp_path):
    src = lambda i: survey_sample(5, i)  # noqa: E731
    cfg = TrainConfig(out=str(tmp_path / "run"), model="ssdlite", steps=3, batch=2, checkpoint_every=1, warmup=1)
    res = train_detector(cfg, src, progress=False, log=lambda *a: None, max_seconds=0.0)
    assert res["steps"] == 1  # stopped after the first step, checkpoint written
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 1 and ck["config"]["model"] == "ssdlite" and "optimizer" in ck
    first = {k: v.clone() for k, v in ck["model"].items()}
    lines = []
    res = train_detector(cfg, src, progress=False, log=lines.append)
    assert res["steps"] == 3 and lines == ["resuming from step 1 of 3"]
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 3
    assert any(not torch.equal(first[k], ck["model"][k]) for k in first if first[k].is_floating_point())
    log = (tmp_path / "run" / "losses.csv").read_text().splitlines()
    assert [line.split(",")[0] for line in log[1:]] == ["1", "2", "3"]
    other = TrainConfig(out=str(tmp_path / "run"), model="ssdlite", steps=3, batch=3, checkpoint_every=1)
    with pytest.raises(GPR3DError, match="other settings"):
        train_detector(other, src, progress=False, log=lambda *a: None)


def test_detector_finds_separate_pipes_at_their_apexes():
    """The shipped detector as ``gpr3d detect`` runs it (with the box refiner): all 9 visible targets found on this
    record, the PVC pipe under a rebar included (stage 5; its network's own boxes, ``Detector.load()``, place one
    rebar's apex 0.163 ns off, past the 0.156 allowed)."""
    det = load_detector(engine="torch")
    s, lab = survey_sample(4242, 3, augment=False)
    res = det.detect(s, score_threshold=0.5)
    true = [(x["apex_trace"], x["apex_time_s"]) for x in lab["labels"] if x["visible"]]
    found = [(t["apex_trace"], t["apex_time_s"]) for t in res["targets"]]
    hits = sum(any(abs(a - b) <= 3 and abs(ta - tb) <= 0.25 / s.frequency_hz for b, tb in found) for a, ta in true)
    assert hits >= 0.8 * len(true), (true, found)
    assert len(found) <= len(true) + 2
    assert all(0 <= t["box"][0] <= t["box"][2] <= s.n_traces - 1 for t in res["targets"])
    assert all(0 <= t["box"][1] < t["box"][3] <= (s.n_samples - 1) * s.dt_s for t in res["targets"])


def test_weight_file_messages_in_full_and_the_window_size_rebuilds_the_model(tmp_path):
    m = build_model("ssdlite")
    save_weights(m, "yolo", WindowConfig().to_dict(), tmp_path / "unknown.pt")
    with pytest.raises(FormatError) as err:
        load_weights(tmp_path / "unknown.pt")
    assert str(err.value) == "unknown.pt: unknown model 'yolo' in the weights file"
    save_weights(m, "frcnn_lean", WindowConfig().to_dict(), tmp_path / "mismatch.pt")
    with pytest.raises(FormatError) as err:
        load_weights(tmp_path / "mismatch.pt")
    try:  # what torch says, second line (the first names the model class)
        build_model("frcnn_lean").load_state_dict({k: v.float() for k, v in m.state_dict().items()})
    except RuntimeError as exc:
        torch_says = str(exc).splitlines()[1].strip()
    assert len(torch_says) > 160
    assert str(err.value) == f"mismatch.pt: weights do not fit model 'frcnn_lean': {torch_says[:160]}"
    small = build_model("ssdlite", image_size=320)
    save_weights(small, "ssdlite", WindowConfig(rows=320, traces=320).to_dict(), tmp_path / "w320.pt", provenance={})
    m2, win, prov = load_weights(tmp_path / "w320.pt")
    assert win.rows == 320 and m2.transform.fixed_size == (320, 320) and prov == {} and not m2.training
    torch.save({k: v for k, v in torch.load(tmp_path / "w320.pt", weights_only=True).items() if k != "provenance"},
               tmp_path / "noprov.pt")
    assert load_weights(tmp_path / "noprov.pt")[2] == {}
