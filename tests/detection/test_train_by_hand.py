"""The training loop by hand: a two-parameter stand-in model and a dataset of numbered items replace torchvision's
detector and the window maker, so that every step runs in milliseconds and what the loop does can be compared,
value by value, with what it must do: which items each step sees (and a resumed run skips), the learning rate of
each step (warm-up then cosine, computed here independently), the logged losses, what each checkpoint holds, and
that a run stopped and resumed ends exactly where an uninterrupted run ends.
"""

import json
import math
import os
from dataclasses import asdict

import pytest

torch = pytest.importorskip("torch")

import gpr3d.detection.data as data_mod  # noqa: E402
import gpr3d.detection.models as models_mod  # noqa: E402
import gpr3d.detection.weights as weights_mod  # noqa: E402
from gpr3d import __version__  # noqa: E402
from gpr3d.core import training  # noqa: E402
from gpr3d.core.errors import GPR3DError, InvalidDataError  # noqa: E402
from gpr3d.detection import train as train_mod  # noqa: E402
from gpr3d.detection.train import TrainConfig, train_detector  # noqa: E402
from gpr3d.detection.windows import WindowConfig  # noqa: E402


class Tiny(torch.nn.Module):
    """Losses ``a = (w0 - x)^2`` and ``b = 0.5 (w1 + x)^2`` of the batch's item numbers ``x``; records what it sees."""

    def __init__(self, seen):
        super().__init__()
        self.w = torch.nn.Parameter(torch.randn(2))
        self.seen = seen

    def forward(self, images, targets):
        x = torch.stack(images).mean()
        self.seen.append(([float(i) for i in images], [int(t["k"]) for t in targets], self.w.detach().clone()))
        self.pids = getattr(self, "pids", set()) | {int(t["pid"]) for t in targets if "pid" in t}
        return {"loss_a": (self.w[0] - x) ** 2 / 100, "loss_b": 0.5 * (self.w[1] + x) ** 2 / 100}


class Items:
    """Item ``k``: the image ``[k]`` and the target ``{"k": k}``; records how it was made."""

    made = []

    def __init__(self, source, n, cfg=None, *, seed=0, flip=True, kinds=None, augment=None):
        Items.made.append({"source": source, "n": n, "cfg": cfg, "seed": seed, **({"kinds": kinds} if kinds else {}),
                           **({"augment": augment} if augment is not None else {})})
        self.n = n

    def __len__(self):
        return self.n

    def __getitem__(self, k):
        return torch.tensor([float(k)]), {"k": torch.tensor(k), "pid": torch.tensor(os.getpid())}


@pytest.fixture
def stand_ins(monkeypatch):
    seen, built = [], []

    def build(name, image_size=256, kinds=None):
        built.append((name, image_size) + ((kinds,) if kinds else ()))
        return Tiny(seen)

    Items.made = []
    monkeypatch.setattr(models_mod, "build_model", build)
    monkeypatch.setattr(data_mod, "WindowDataset", Items)
    return {"seen": seen, "built": built}


def quiet(*a):
    pass


def cfg_for(tmp_path, **kw):
    base = dict(out=str(tmp_path / "run"), model="ssdlite", steps=5, batch=2, checkpoint_every=2, warmup=2, seed=3,
                data_seed=77, window={**WindowConfig().to_dict(), "rows": 64})
    return TrainConfig(**{**base, **kw})


def lr_at(k, base, warmup, steps, floor=0.02):
    """The learning rate after ``k`` scheduler steps, from the formula (linear warm-up, cosine to 2 %)."""
    if k < warmup:
        return base * (k + 1) / warmup
    p = min((k - warmup) / max(steps - warmup, 1), 1.0)
    return base * (floor + (1 - floor) * 0.5 * (1 + math.cos(math.pi * p)))


def test_a_whole_run_sees_each_item_once_in_order_and_logs_every_step(tmp_path, stand_ins):
    cfg = cfg_for(tmp_path)
    res = train_detector(cfg, "the source", progress=False, log=quiet)
    assert stand_ins["built"] == [("ssdlite", 64)]
    assert Items.made == [{"source": "the source", "n": 10, "cfg": WindowConfig(**cfg.window), "seed": 77}]
    seen = stand_ins["seen"]
    assert [s[1] for s in seen] == [[0, 1], [2, 3], [4, 5], [6, 7], [8, 9]]
    assert [s[0] for s in seen] == [[0.0, 1.0], [2.0, 3.0], [4.0, 5.0], [6.0, 7.0], [8.0, 9.0]]
    torch.manual_seed(3)
    assert torch.equal(seen[0][2], torch.randn(2))  # the model was made right after seeding with cfg.seed
    assert res["steps"] == 5 and res["parameters"] == 2 and res["checkpoint"] == str(tmp_path / "run/checkpoint.pt")
    assert 0 < res["wall_s"] < 600 and isinstance(res["model"], Tiny)
    assert res["kinds"] is None and res["model"].gpr3d_kinds is None  # (one class: what gpr3d train saves with)
    lines = (tmp_path / "run" / "losses.csv").read_text().splitlines()
    assert lines[0] == "step,lr,loss,wall_s,terms"
    assert len(lines) == 6
    for k, (line, (_, items, w)) in enumerate(zip(lines[1:], seen)):
        step, lr, loss, wall, terms = line.split(",")
        x = sum(items) / len(items)
        a, b = float((w[0] - x) ** 2 / 100), float(0.5 * (w[1] + x) ** 2 / 100)
        assert int(step) == k + 1
        assert float(lr) == pytest.approx(lr_at(k + 1, 1e-3, 2, 5), rel=2e-3)  # written to 3 digits
        assert float(loss) == pytest.approx(a + b, abs=6e-6)
        ta, tb = terms.split(";")
        assert ta.startswith("loss_a=") and float(ta[7:]) == pytest.approx(a, abs=6e-6)
        assert tb.startswith("loss_b=") and float(tb[7:]) == pytest.approx(b, abs=6e-6)
        assert 0 <= float(wall) < 600
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 5 and ck["epoch"] == 0 and ck["windows_seen"] == 10 and ck["gpr3d"] == __version__
    assert ck["config"] == asdict(cfg)
    assert ck["resume_key"] == {k: v for k, v in asdict(cfg).items()  # (no wall share: keys as before it existed)
                                if k not in ("device", "workers", "checkpoint_every", "out", "wall_fraction",
                                             "wall_box_pad", "wall_pad_wavelet")}
    assert torch.equal(ck["model"]["w"], res["model"].w.detach())
    assert ck["optimizer"]["param_groups"][0]["lr"] == pytest.approx(lr_at(5, 1e-3, 2, 5), rel=1e-12)
    assert ck["scheduler"]["last_epoch"] == 5
    saved = (tmp_path / "run" / "config.json").read_text()
    assert saved == json.dumps({"gpr3d": __version__, "config": asdict(cfg)}, indent=2)  # for people to read


def test_checkpoints_every_n_steps_and_at_the_end(tmp_path, stand_ins, monkeypatch):
    steps = []
    real = torch.save
    monkeypatch.setattr(torch, "save", lambda state, f: (steps.append(state["step"]), real(state, f)))
    train_detector(cfg_for(tmp_path, steps=7, checkpoint_every=3), None, progress=False, log=quiet)
    assert steps == [3, 6, 7]
    assert not list((tmp_path / "run").glob("*.part"))


def test_a_stopped_run_resumes_and_ends_where_an_unbroken_run_ends(tmp_path, stand_ins):
    whole = train_detector(cfg_for(tmp_path / "a"), None, progress=False, log=quiet)
    stand_ins["seen"].clear()
    logged = []
    cfg = cfg_for(tmp_path / "b", checkpoint_every=100)
    first = train_detector(cfg, None, progress=False, log=logged.append, max_seconds=0.0)
    assert first["steps"] == 1
    assert logged == ["stopped after 0 s at step 1; run again to continue"]
    ck = torch.load(tmp_path / "b" / "run" / "checkpoint.pt", weights_only=True)
    assert ck["step"] == 1 and ck["windows_seen"] == 2
    logged.clear()
    stand_ins["seen"].clear()
    again = train_detector(cfg, None, progress=False, log=logged.append)
    assert logged == ["resuming from step 1 of 5"]
    assert [s[1] for s in stand_ins["seen"]] == [[2, 3], [4, 5], [6, 7], [8, 9]]
    assert again["steps"] == 5
    assert torch.equal(again["model"].w, whole["model"].w)  # optimiser and schedule state carried over exactly
    lines = (tmp_path / "b" / "run" / "losses.csv").read_text().splitlines()
    assert lines[0] == "step,lr,loss,wall_s,terms" and [ln.split(",")[0] for ln in lines[1:]] == list("12345")
    # the logged learning rates are the same as the unbroken run's
    a_lr = [ln.split(",")[1] for ln in (tmp_path / "a" / "run" / "losses.csv").read_text().splitlines()[1:]]
    assert [ln.split(",")[1] for ln in lines[1:]] == a_lr


def test_a_finished_run_run_again_does_nothing_more(tmp_path, stand_ins):
    cfg = cfg_for(tmp_path)
    done = train_detector(cfg, None, progress=False, log=quiet)
    stand_ins["seen"].clear()
    logged = []
    again = train_detector(cfg, None, progress=False, log=logged.append)
    assert stand_ins["seen"] == [] and again["steps"] == 5 and logged == ["resuming from step 5 of 5"]
    assert torch.equal(again["model"].w, done["model"].w)
    assert len((tmp_path / "run" / "losses.csv").read_text().splitlines()) == 6


def test_settings_that_only_say_how_to_run_may_change_on_resume(tmp_path, stand_ins):
    train_detector(cfg_for(tmp_path, steps=2), None, progress=False, log=quiet, max_seconds=0.0)
    logged = []
    train_detector(cfg_for(tmp_path, steps=2, checkpoint_every=7, workers=0, device="cpu"), None, progress=False,
                   log=logged.append)
    assert logged == ["resuming from step 1 of 2"]
    for kw in ({"steps": 3}, {"batch": 3}, {"seed": 4}, {"data_seed": 78}, {"lr": 2e-3}, {"warmup": 1},
               {"wall_fraction": 0.5}):
        with pytest.raises(GPR3DError) as err:
            train_detector(cfg_for(tmp_path, **{"steps": 2, **kw}), None, wall_source="walls", progress=False,
                           log=quiet)
        assert str(err.value) == (f"{tmp_path / 'run' / 'checkpoint.pt'}: made with other settings; use another --out "
                                  "or delete the checkpoint")


def test_an_unreadable_checkpoint_is_named(tmp_path, stand_ins):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "checkpoint.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path), None, progress=False, log=quiet)
    with pytest.raises(Exception) as direct:
        torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert str(err.value) == (f"{tmp_path / 'run' / 'checkpoint.pt'}: cannot read the checkpoint "
                              f"({type(direct.value).__name__}); delete it to restart")


def test_a_checkpoint_holding_code_is_not_loaded(tmp_path, stand_ins):
    """Checkpoints are read with ``weights_only``: one that would unpickle an arbitrary object is refused."""
    from fractions import Fraction

    (tmp_path / "run").mkdir()
    torch.save({"step": 1, "resume_key": None, "payload": Fraction(1, 3)}, tmp_path / "run" / "checkpoint.pt")
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path), None, progress=False, log=quiet)
    assert str(err.value) == (f"{tmp_path / 'run' / 'checkpoint.pt'}: cannot read the checkpoint (UnpicklingError); "
                              "delete it to restart")


def test_a_restart_after_deleting_the_checkpoint_starts_a_new_log(tmp_path, stand_ins):
    cfg = cfg_for(tmp_path)
    train_detector(cfg, None, progress=False, log=quiet)
    (tmp_path / "run" / "checkpoint.pt").unlink()
    train_detector(cfg, None, progress=False, log=quiet)
    lines = (tmp_path / "run" / "losses.csv").read_text().splitlines()
    assert lines[0] == "step,lr,loss,wall_s,terms" and [ln.split(",")[0] for ln in lines[1:]] == list("12345")


def test_data_loading_processes_as_asked(tmp_path, stand_ins):
    one = train_detector(cfg_for(tmp_path / "a", steps=2, workers=1), None, progress=False, log=quiet)
    assert one["model"].pids and os.getpid() not in one["model"].pids
    none = train_detector(cfg_for(tmp_path / "b", steps=2), None, progress=False, log=quiet)
    assert none["model"].pids == {os.getpid()}
    assert [s[1] for s in stand_ins["seen"][:2]] == [s[1] for s in stand_ins["seen"][2:]]  # the same items


def test_a_device_that_is_not_here_is_named_before_any_work(tmp_path, stand_ins):
    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path, device="cuda:0"), None, progress=False, log=quiet)
    assert str(err.value) == "--device cuda:0: CUDA is not available on this machine (use --device cpu)"
    assert stand_ins["built"] == [] and not (tmp_path / "run" / "losses.csv").exists()


def test_a_diverging_loss_stops_with_the_step_named(tmp_path, stand_ins, monkeypatch):
    class Nan(Items):
        def __getitem__(self, k):
            return torch.tensor([float("nan") if k >= 4 else float(k)]), {"k": torch.tensor(k)}

    monkeypatch.setattr(data_mod, "WindowDataset", Nan)
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path), None, progress=False, log=quiet)
    assert str(err.value) == "training diverged at step 2 (loss nan); lower --lr"
    assert len((tmp_path / "run" / "losses.csv").read_text().splitlines()) == 3  # two steps logged, file closed


def test_the_progress_bar_only_when_asked(tmp_path, stand_ins, capsys):
    train_detector(cfg_for(tmp_path / "a"), None, progress=False, log=quiet)
    assert capsys.readouterr().err == ""
    train_detector(cfg_for(tmp_path / "b"), None, progress=True, log=quiet)
    err = capsys.readouterr().err
    assert "train ssdlite" in err and "5/5" in err and "loss=" in err
    train_detector(cfg_for(tmp_path / "c"), None, log=quiet)  # shown by default
    assert "5/5" in capsys.readouterr().err


def test_init_weights_start_the_model_or_are_refused(tmp_path, stand_ins, monkeypatch):
    start = Tiny([])
    with torch.no_grad():
        start.w.copy_(torch.tensor([0.25, -0.5]))
    window = WindowConfig(**cfg_for(tmp_path).window)
    asked = []
    monkeypatch.setattr(weights_mod, "load_weights", lambda path: (asked.append(path), (start, window, {}))[1])
    train_detector(cfg_for(tmp_path / "a", init="w.pt"), None, progress=False, log=quiet)
    assert asked == ["w.pt"]
    assert torch.equal(stand_ins["seen"][0][2], torch.tensor([0.25, -0.5]))

    monkeypatch.setattr(weights_mod, "load_weights", lambda path: (torch.nn.Linear(2, 2), window, {}))
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path / "b", init="w.pt"), None, progress=False, log=quiet)
    assert str(err.value) == "--init w.pt: made for another model or window; it cannot start 'ssdlite'"

    other_window = WindowConfig(**{**window.to_dict(), "rows": 128})
    monkeypatch.setattr(weights_mod, "load_weights", lambda path: (start, other_window, {}))
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path / "c", init="w.pt"), None, progress=False, log=quiet)
    assert str(err.value) == "--init w.pt: made for another model or window; it cannot start 'ssdlite'"

    bigger = Tiny([])
    bigger.w = torch.nn.Parameter(torch.zeros(3))
    monkeypatch.setattr(weights_mod, "load_weights", lambda path: (bigger, window, {}))
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path / "d", init="w.pt"), None, progress=False, log=quiet)
    assert str(err.value) == "--init w.pt: its weights do not fit 'ssdlite'"


class _Rec:
    """A stand-in record source: notes how it was made in ``made``."""

    made: list = []

    def __init__(self, *a, **kw):
        _Rec.made.append((type(self).__name__, a, kw))


class PackedSource(_Rec):
    pass


class MixedSource(_Rec):
    pass


class RecordsSource(_Rec):
    def __init__(self, records):
        super().__init__(records)
        self.records, self.n_boxes = records, 7


@pytest.fixture
def sources(monkeypatch):
    """The data module's sources replaced by stand-ins; returns the list of what was made, in order."""
    _Rec.made = []
    for cls in (PackedSource, MixedSource, RecordsSource):
        monkeypatch.setattr(data_mod, cls.__name__, cls)
    return _Rec.made


def test_packed_and_user_labels_are_mixed_in(tmp_path, stand_ins, sources, monkeypatch):
    made = sources
    import gpr3d.io.userlabels as userlabels

    monkeypatch.setattr(userlabels, "read_user_labels", lambda path, pixel_map=None: [("rec", path, pixel_map)] * 3)
    logged = []
    cfg = cfg_for(tmp_path, steps=1, packed=["a.h5:5", "b.h5"], packed_fraction=0.3, packed_holdout=9,
                  labels="mine.json", labels_fraction=0.25, pixel_map="s_per_px=1e-10,t0_s=0")
    train_detector(cfg, "gen", progress=False, log=logged.append)
    assert [m[0] for m in made] == ["PackedSource", "MixedSource", "RecordsSource", "MixedSource"]
    assert made[0][1:] == ((["a.h5:5", "b.h5"],), {"holdout": 9})
    assert made[1][1][0] == "gen" and isinstance(made[1][1][1], PackedSource) and made[1][1][2] == 0.3
    assert made[1][2] == {"salt": 0x314}  # inside the labels' mix: a draw of its own
    assert made[3][2] == {}  # the outer mix: the default draw
    assert made[2][1] == ([("rec", "mine.json", "s_per_px=1e-10,t0_s=0")] * 3,)
    assert isinstance(made[3][1][0], MixedSource) and isinstance(made[3][1][1], RecordsSource)
    assert made[3][1][2] == 0.25
    assert logged == ["3 labelled record(s), 7 box(es) from mine.json: 25% of the windows"]
    assert isinstance(Items.made[-1]["source"], MixedSource)
    # packed records alone (the stage-3 recipe): the default draw, as that run made it
    made.clear()
    train_detector(cfg_for(tmp_path / "alone", steps=1, packed=["a.h5"], packed_fraction=0.6), "gen", progress=False)
    assert [m[0] for m in made] == ["PackedSource", "MixedSource"] and made[1][2] == {}


def test_wall_scans_are_mixed_in_first_with_a_draw_of_their_own(tmp_path, stand_ins, sources):
    made = sources
    cfg = cfg_for(tmp_path, steps=1, wall_fraction=0.4, packed=["a.h5"], packed_fraction=0.6)
    train_detector(cfg, "gen", wall_source="walls", progress=False, log=quiet)
    assert [m[0] for m in made] == ["MixedSource", "PackedSource", "MixedSource"]
    assert made[0][1:] == (("gen", "walls", 0.4), {"salt": 0x315})  # apart from the packed (0x314), labels' (0x313)
    assert made[2][1][0] is not None and isinstance(made[2][1][0], MixedSource) and made[2][1][2] == 0.6
    assert Items.made[-1]["source"] is not None and isinstance(Items.made[-1]["source"], MixedSource)
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["resume_key"]["wall_fraction"] == 0.4  # a different share is another run
    made.clear()  # none asked: the source as given, and no wall source needed
    train_detector(cfg_for(tmp_path / "none", steps=1), "gen", progress=False, log=quiet)
    assert made == [] and Items.made[-1]["source"] == "gen"


def test_a_wall_share_without_wall_scans_is_refused_before_any_work(tmp_path, stand_ins):
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path, wall_fraction=0.3), "gen", progress=False, log=quiet)
    assert str(err.value) == "--wall-fraction 0.3: no wall-scan source was given to draw them from"
    assert stand_ins["built"] == [] and not (tmp_path / "run").exists()


def test_a_run_from_before_the_wall_share_resumes(tmp_path, stand_ins):
    cfg = cfg_for(tmp_path, steps=2)
    train_detector(cfg, None, progress=False, log=quiet, max_seconds=0.0)
    ck_path = tmp_path / "run" / "checkpoint.pt"
    ck = torch.load(ck_path, weights_only=True)
    assert "wall_fraction" not in ck["resume_key"]  # what an older gpr3d wrote
    logged = []
    train_detector(cfg, None, progress=False, log=logged.append)
    assert logged == ["resuming from step 1 of 2"]


@pytest.mark.parametrize("opt, lr, wd, cls, want_lr, want_wd, momentum", [
    ("adamw", None, None, "AdamW", 1e-3, 1e-4, None),
    ("adamw", 5e-4, 0.0, "AdamW", 5e-4, 0.0, None),
    ("sgd", None, None, "SGD", 0.02, 1e-4, 0.9),
    ("sgd", 0.1, 1e-3, "SGD", 0.1, 1e-3, 0.9),
    ("reference", None, None, "SGD", 4e-5, 5e-5, 0.9),
])
def test_optimisers_and_their_defaults(tmp_path, opt, lr, wd, cls, want_lr, want_wd, momentum):
    cfg = cfg_for(tmp_path, optimiser=opt, lr=lr, weight_decay=wd)
    assert cfg.resolved_lr() == want_lr
    o = train_mod._optimiser(cfg, [torch.nn.Parameter(torch.zeros(1))])
    assert type(o).__name__ == cls
    g = o.param_groups[0]
    assert g["lr"] == want_lr and g["weight_decay"] == want_wd
    if momentum is not None:
        assert g["momentum"] == momentum
    assert len(g["params"]) == 1


@pytest.mark.parametrize("kw, msg", [
    ({"model": "yolo9"}, "unknown detector 'yolo9'; choose one of "),
    ({"optimiser": "adam"}, "unknown optimiser 'adam'; choose one of adamw, sgd, reference"),
    ({"steps": 0}, "--steps must be an integer >= 1, got 0"),
    ({"steps": 2.0}, "--steps must be an integer >= 1, got 2.0"),
    ({"batch": 1}, "--batch must be an integer >= 2, got 1 (batch norm needs two windows a step)"),
    ({"checkpoint_every": 0}, "--checkpoint-every must be an integer >= 1, got 0"),
    ({"warmup": 0}, "--warmup must be an integer >= 1, got 0"),
    ({"seed": -1}, "--seed must be an integer >= 0, got -1"),
    ({"data_seed": -1}, "--data-seed must be an integer >= 0, got -1"),
    ({"workers": -1}, "--workers must be 0 or more, got -1"),
    ({"workers": 1.0}, "--workers must be 0 or more, got 1.0"),
    ({"lr": 0.0}, "--lr must lie in (0, 10), got 0.0"),
    ({"lr": 10.0}, "--lr must lie in (0, 10), got 10.0"),
    ({"packed_fraction": -0.1}, "--packed-fraction must lie in 0..1, got -0.1"),
    ({"packed_fraction": 1.01}, "--packed-fraction must lie in 0..1, got 1.01"),
    ({"packed_holdout": -1}, "--packed-holdout must be 0 or more, got -1"),
    ({"packed_holdout": 2.5}, "--packed-holdout must be 0 or more, got 2.5"),
    ({"labels_fraction": -0.5}, "--labels-fraction must lie in 0..1, got -0.5"),
    ({"labels_fraction": 2.0}, "--labels-fraction must lie in 0..1, got 2.0"),
    ({"window": {"rows": 8}}, "window rows must be an integer in 32..2048, got 8"),
    ({"wall_fraction": -0.1}, "--wall-fraction must lie in 0..1, got -0.1"),
    ({"wall_fraction": 1.5}, "--wall-fraction must lie in 0..1, got 1.5"),
])
def test_train_config_names_each_wrong_value_in_full(tmp_path, kw, msg):
    with pytest.raises(InvalidDataError) as err:
        TrainConfig(out=str(tmp_path), **kw)
    if msg.endswith("choose one of "):
        assert str(err.value) == msg + ", ".join(models_mod.MODELS)
    else:
        assert str(err.value) == msg


def test_train_config_edges_that_are_allowed(tmp_path):
    TrainConfig(out=str(tmp_path), steps=1, batch=2, checkpoint_every=1, warmup=1, seed=0, data_seed=0, workers=0,
                lr=9.99, packed_fraction=0.0, labels_fraction=1.0, packed_holdout=0)
    TrainConfig(out=str(tmp_path), packed_fraction=1.0, labels_fraction=0.0, lr=1e-9, wall_fraction=1.0)
    assert TrainConfig(out="x").wall_fraction == 0.0
    cfg = TrainConfig(out=str(tmp_path), init="default")
    assert cfg.init == str(weights_mod.DEFAULT_WEIGHTS)
    assert TrainConfig(out=str(tmp_path)).init is None
    d = TrainConfig(out="x")
    assert (d.model, d.steps, d.batch, d.lr, d.optimiser, d.warmup, d.seed, d.data_seed, d.workers,
            d.checkpoint_every, d.packed_fraction, d.packed_holdout, d.labels_fraction) == (
        "frcnn_lean", 3000, 8, None, "adamw", 200, 0, 1000, 0, 100, 0.2, 60, 0.5)
    assert d.window == WindowConfig().to_dict()


def test_augment_is_named_in_the_config_and_reaches_the_windows(tmp_path, stand_ins):
    from gpr3d.detection.augment import Augment

    assert TrainConfig(out="x").augment is None and TrainConfig(out="x", augment=False).augment is None
    assert TrainConfig(out="x", augment=True).augment == {"stretch": [0.7, 1.4], "gain": [0.6, 1.8], "noise": 0.15}
    assert TrainConfig(out="x", augment={"noise": 0.3, "stretch": (0.9, 1.1)}).augment == {
        "stretch": [0.9, 1.1], "gain": [0.6, 1.8], "noise": 0.3}
    for bad, msg in (({"blur": 1}, r"^--augment takes stretch, gain and noise, got \['blur'\]$"),
                     ({"noise": 2.0}, "^augment noise must lie in 0..1, got 2.0$"),
                     ("yes", "^--augment must be on, off or a dict of ranges, got 'yes'$")):
        with pytest.raises(InvalidDataError, match=msg):
            TrainConfig(out="x", augment=bad)
    cfg = cfg_for(tmp_path, augment={"gain": [0.5, 2.0]})
    train_detector(cfg, "src", progress=False, log=quiet)
    assert Items.made[-1]["augment"] == Augment(gain=(0.5, 2.0))
    train_detector(cfg_for(tmp_path, out=str(tmp_path / "plain")), "src", progress=False, log=quiet)
    assert "augment" not in Items.made[-1]
    # a run with other ranges is another run: its checkpoint is not resumed from
    with pytest.raises(GPR3DError):
        train_detector(cfg_for(tmp_path, augment=True), "src", progress=False, log=quiet)


def test_a_run_times_its_steps_and_stops_when_late(tmp_path, stand_ins, monkeypatch, step_clock):
    monkeypatch.setattr(training, "time", step_clock())  # (the engine keeps the time)
    res = train_detector(cfg_for(tmp_path / "a", steps=3), None, progress=False, log=quiet)
    lines = (tmp_path / "a" / "run" / "losses.csv").read_text().splitlines()[1:]
    assert [ln.split(",")[3] for ln in lines] == ["0.5", "1.0", "1.5"] and res["wall_s"] == 2.0
    monkeypatch.setattr(training, "time", step_clock())  # (the engine keeps the time)
    logged = []
    res = train_detector(cfg_for(tmp_path / "b"), None, progress=False, log=logged.append, max_seconds=1.0)
    # step 1 is logged at 0.5 s and checked at 1.0 s (not past 1 s); step 2 checked at 2.0 s
    assert res["steps"] == 2 and logged == ["stopped after 1 s at step 2; run again to continue"]


def test_the_bar_counts_on_from_where_a_run_resumes(tmp_path, stand_ins, capsys):
    import re

    cfg = cfg_for(tmp_path)
    train_detector(cfg, None, progress=False, log=quiet, max_seconds=0.0)  # one step
    capsys.readouterr()
    train_detector(cfg, None, progress=True, log=quiet)
    last = capsys.readouterr().err.rstrip().split("\r")[-1]
    assert last.startswith("train ssdlite: 100%") and "| 5/5 [" in last, last
    assert re.search(r"\d(step/s|s/step), loss=\d+\.\d{3}\]$", last), last


class _Walls:
    def __init__(self, box_pad=None, pad_wavelet=False):
        self.box_pad, self.pad_wavelet = box_pad, pad_wavelet


def test_the_wall_records_box_pad_is_part_of_the_run_and_must_be_the_source_s(tmp_path, stand_ins, sources):
    cfg = cfg_for(tmp_path, steps=1, wall_fraction=0.4, wall_box_pad=0.4)
    with pytest.raises(GPR3DError) as err:  # a source that pads otherwise: refused before any work
        train_detector(cfg, "gen", wall_source=_Walls(), progress=False, log=quiet)
    assert str(err.value) == "--wall-box-pad 0.4: the wall-scan source given pads its boxes by None"
    assert stand_ins["built"] == []
    with pytest.raises(GPR3DError) as err:  # a source that names no pad (the default rule's)
        train_detector(cfg, "gen", wall_source="walls", progress=False, log=quiet)
    assert str(err.value) == "--wall-box-pad 0.4: the wall-scan source given pads its boxes by None"
    train_detector(cfg, "gen", wall_source=_Walls(0.4), progress=False, log=quiet)
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["resume_key"]["wall_box_pad"] == 0.4  # another pad is another run
    with pytest.raises(GPR3DError, match="the wall-scan source given pads its boxes by 0.4"):
        train_detector(cfg_for(tmp_path / "b", steps=1, wall_fraction=0.4), "gen", wall_source=_Walls(0.4),
                       progress=False, log=quiet)
    train_detector(cfg_for(tmp_path / "c", steps=1, wall_fraction=0.4), "gen", wall_source=_Walls(),
                   progress=False, log=quiet)
    ck = torch.load(tmp_path / "c" / "run" / "checkpoint.pt", weights_only=True)
    assert "wall_box_pad" not in ck["resume_key"]  # (none asked: runs from before the setting resume)


@pytest.mark.parametrize("kw, msg", [
    (dict(wall_fraction=0.4, wall_box_pad=-0.1), "--wall-box-pad must lie in 0..2 periods, got -0.1"),
    (dict(wall_fraction=0.4, wall_box_pad=float("nan")), "--wall-box-pad must lie in 0..2 periods, got nan"),
    (dict(wall_fraction=0.4, wall_box_pad="0.4"), "--wall-box-pad must lie in 0..2 periods, got '0.4'"),
    (dict(wall_box_pad=0.4), "--wall-box-pad sets the wall records' boxes: give --wall-fraction too"),
])
def test_a_wrong_wall_box_pad_is_one_line(tmp_path, kw, msg):
    with pytest.raises(InvalidDataError) as err:
        cfg_for(tmp_path, **kw)
    assert str(err.value) == msg


@pytest.mark.parametrize("pad, ok", [(0.0, True), (2.0, True), (2.5, False), (-1e-9, False)])
def test_a_wall_box_pad_lies_in_0_to_2_periods_ends_included(tmp_path, pad, ok):
    if ok:
        assert cfg_for(tmp_path, wall_fraction=0.4, wall_box_pad=pad).wall_box_pad == pad
    else:
        with pytest.raises(InvalidDataError, match="--wall-box-pad must lie in 0..2 periods"):
            cfg_for(tmp_path, wall_fraction=0.4, wall_box_pad=pad)


def test_a_pad_in_the_wavelet_s_periods_is_part_of_the_run_and_must_be_the_source_s(tmp_path, stand_ins, sources):
    cfg = cfg_for(tmp_path, steps=1, wall_fraction=0.4, wall_pad_wavelet=True)
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg, "gen", wall_source=_Walls(), progress=False, log=quiet)
    assert str(err.value) == "--wall-pad-wavelet True: the wall-scan source given pads by the label's frequency"
    with pytest.raises(GPR3DError) as err:
        train_detector(cfg_for(tmp_path / "b", steps=1, wall_fraction=0.4), "gen",
                       wall_source=_Walls(pad_wavelet=True), progress=False, log=quiet)
    assert str(err.value) == "--wall-pad-wavelet False: the wall-scan source given pads by the drawn wavelet's frequency"
    assert stand_ins["built"] == []
    train_detector(cfg, "gen", wall_source=_Walls(pad_wavelet=True), progress=False, log=quiet)
    ck = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=True)
    assert ck["resume_key"]["wall_pad_wavelet"] is True and "wall_box_pad" not in ck["resume_key"]
    for kw, msg in ((dict(wall_pad_wavelet=True), "--wall-pad-wavelet sets the wall records' boxes: give "
                     "--wall-fraction too"),
                    (dict(wall_fraction=0.4, wall_pad_wavelet="yes"), "--wall-pad-wavelet is true or false, got 'yes'")):
        with pytest.raises(InvalidDataError) as err:
            cfg_for(tmp_path, **kw)
        assert str(err.value) == msg
