"""The training loops' shared schedule and step."""

import math

import pytest

from gpr3d.core.errors import GPR3DError
from gpr3d.core.training import optimiser_step, warmup_cosine


def test_warmup_then_cosine_down_to_the_floor():
    f = warmup_cosine(4, 14, floor=0.1)
    assert [f(k) for k in range(4)] == pytest.approx([0.25, 0.5, 0.75, 1.0])
    assert f(4) == pytest.approx(1.0)
    assert f(9) == pytest.approx(0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * 0.5)))  # half-way: 0.55
    assert f(14) == pytest.approx(0.1) and f(100) == pytest.approx(0.1)


def test_a_step_moves_the_weights_and_a_bad_loss_stops_in_one_line():
    torch = pytest.importorskip("torch")
    model = torch.nn.Linear(2, 1, bias=False)
    torch.nn.init.constant_(model.weight, 1.0)
    opt = torch.optim.SGD(model.parameters(), lr=0.1)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0)
    x = torch.tensor([[1.0, 2.0]])
    optimiser_step(model, opt, sched, model(x).sum(), 0, max_norm=100.0)
    assert model.weight.detach().tolist()[0] == pytest.approx([0.9, 0.8])  # w - lr * x
    with pytest.raises(GPR3DError, match="DepthNet training diverged at step 7"):
        optimiser_step(model, opt, sched, model(x).sum() * float("nan"), 7, what="DepthNet training")


def _linear_run(torch, out, *, steps=5, every=2, key=None, max_seconds=None, logged=None):
    from gpr3d.core.training import TrainingRun

    torch.manual_seed(0)
    model = torch.nn.Linear(2, 1, bias=False)
    torch.nn.init.constant_(model.weight, 1.0)
    opt = torch.optim.SGD(model.parameters(), lr=0.1)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0 / (k + 1))
    return model, TrainingRun(out, model, opt, sched, steps=steps, resume_key=key or {"lr": 0.1},
                              config={"config": {"lr": 0.1}}, columns="step,lr,loss,x,wall_s",
                              checkpoint_every=every, progress=False, max_seconds=max_seconds,
                              log=(logged if logged is not None else []).append,
                              extra_state=lambda k: {"seen": 3 * k})


def _batches(torch, start, steps):
    return (torch.tensor([[1.0, float(k)]]) for k in range(start, steps))


def _step_fn(model):
    return lambda x: (model(x).sum(), {"x": f"{float(x[0, 1]):g}"}, {"x": float(x[0, 1])})


def _by_hand(steps):
    """SGD on loss = w . x with x_k = (1, k), lr 0.1 / (k + 1): w -= lr_k x_k."""
    w = [1.0, 1.0]
    for k in range(steps):
        lr = 0.1 / (k + 1)
        w = [w[0] - lr * 1.0, w[1] - lr * k]
    return w


def test_a_run_steps_logs_and_checkpoints_as_its_settings_say(tmp_path):
    torch = pytest.importorskip("torch")
    model, run = _linear_run(torch, tmp_path / "r", steps=5, every=2)
    assert run.step == 0
    run.run(_batches(torch, 0, 9), _step_fn(model))  # (more batches than steps: it stops at 5)
    assert run.step == 5 and run.wall_s > 0
    assert model.weight.detach().tolist()[0] == pytest.approx(_by_hand(5), rel=1e-6)
    rows = (tmp_path / "r" / "losses.csv").read_text().splitlines()
    assert rows[0] == "step,lr,loss,x,wall_s" and len(rows) == 6
    for k, row in enumerate(rows[1:]):
        step, lr, loss, x, wall = row.split(",")
        w = _by_hand(k)
        # the row of step k + 1: the lr after the scheduler's step, the loss before the update, x of batch k
        assert (int(step), float(x)) == (k + 1, k)
        assert float(lr) == pytest.approx(0.1 / (k + 2), rel=1e-2)
        assert float(loss) == pytest.approx(w[0] + w[1] * k, abs=1e-5) and float(wall) >= 0
    ck = torch.load(run.checkpoint, weights_only=True)
    assert ck["step"] == 5 and ck["seen"] == 15 and ck["resume_key"] == {"lr": 0.1} and "gpr3d" in ck
    import json

    cfg = json.loads((tmp_path / "r" / "config.json").read_text())
    assert cfg["config"] == {"lr": 0.1} and "gpr3d" in cfg


def test_a_resumed_run_ends_where_an_unbroken_one_does(tmp_path):
    torch = pytest.importorskip("torch")
    model, run = _linear_run(torch, tmp_path / "a", steps=7, every=2)
    run.run(_batches(torch, 0, 7), _step_fn(model))
    whole = model.weight.detach().clone()
    # the same run stopped after 3 steps: the checkpoint of step 3 is written as the batches run out
    model, run = _linear_run(torch, tmp_path / "b", steps=7, every=2)
    run.run(_batches(torch, 0, 3), _step_fn(model))
    assert torch.load(run.checkpoint, weights_only=True)["step"] == 3
    said = []
    model, run = _linear_run(torch, tmp_path / "b", steps=7, every=2, logged=said)
    assert run.step == 3 and said == ["resuming from step 3 of 7"]
    assert model.weight.detach().tolist()[0] == pytest.approx(_by_hand(3), rel=1e-6)  # the model restored
    assert run.sched.last_epoch == 3 and run.opt.param_groups[0]["lr"] == pytest.approx(0.1 / 4)
    run.run(_batches(torch, run.step, 7), _step_fn(model))
    torch.testing.assert_close(model.weight.detach(), whole)
    a = (tmp_path / "a" / "losses.csv").read_text().splitlines()
    b = (tmp_path / "b" / "losses.csv").read_text().splitlines()
    assert [r.rsplit(",", 1)[0] for r in a] == [r.rsplit(",", 1)[0] for r in b]  # each step once (wall aside)


def test_other_settings_are_refused_and_a_time_limit_stops_with_a_checkpoint(tmp_path):
    torch = pytest.importorskip("torch")
    model, run = _linear_run(torch, tmp_path / "r", steps=4, every=10)
    run.run(_batches(torch, 0, 1), _step_fn(model))
    with pytest.raises(GPR3DError, match=r"checkpoint.pt: made with other settings; use another --out"):
        _linear_run(torch, tmp_path / "r", steps=4, key={"lr": 0.2})
    said = []
    model, run = _linear_run(torch, tmp_path / "t", steps=50, every=100, max_seconds=0.0, logged=said)
    run.run(_batches(torch, 0, 50), _step_fn(model))
    assert run.step == 1 and said == ["stopped after 0 s at step 1; run again to continue"]
    assert torch.load(run.checkpoint, weights_only=True)["step"] == 1
    # a loss that is not finite: one line naming the step, nothing saved past the last good checkpoint
    model, run = _linear_run(torch, tmp_path / "n", steps=6, every=2)
    bad = (torch.tensor([[1.0, float("nan") if k == 3 else float(k)]]) for k in range(6))
    with pytest.raises(GPR3DError, match="training diverged at step 3"):
        run.run(bad, _step_fn(model))
    assert torch.load(run.checkpoint, weights_only=True)["step"] == 2
    assert len((tmp_path / "n" / "losses.csv").read_text().splitlines()) == 4


def test_the_schedule_s_and_step_s_defaults():
    torch = pytest.importorskip("torch")
    f = warmup_cosine(2, 12)  # the default floor: 2 % of the rate at the end
    assert f(12) == pytest.approx(0.02) and f(7) == pytest.approx(0.02 + 0.98 * 0.5)
    g = warmup_cosine(3, 4)  # one step after the warm-up: the cosine runs over that one step
    assert g(3) == pytest.approx(1.0) and g(4) == pytest.approx(0.02)
    # gradients are clipped to a norm of 10 by default: a loss of 100 * w . (3, 4) has a gradient of norm 500
    model = torch.nn.Linear(2, 1, bias=False)
    torch.nn.init.constant_(model.weight, 0.0)
    opt = torch.optim.SGD(model.parameters(), lr=1.0)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0)
    optimiser_step(model, opt, sched, (model(torch.tensor([[3.0, 4.0]])) * 100).sum(), 0)
    assert model.weight.detach().tolist()[0] == pytest.approx([-6.0, -8.0], rel=1e-5)  # 10 * (3, 4) / 5
    with pytest.raises(GPR3DError, match="^training diverged at step 4 "):
        optimiser_step(model, opt, sched, torch.tensor(float("inf"), requires_grad=True), 4)


def test_a_checkpoint_that_is_not_plain_tensors_is_refused_in_one_line(tmp_path):
    torch = pytest.importorskip("torch")
    from gpr3d.core.training import read_checkpoint

    p = tmp_path / "checkpoint.pt"
    torch.save({"step": 3, "f": _Unpicklable()}, p)  # an object: loading it would run code
    with pytest.raises(GPR3DError, match=r"checkpoint.pt: cannot read the checkpoint \(UnpicklingError\); "
                                         r"delete it to restart$"):
        read_checkpoint(p, "cpu")
    torch.save({"step": 3, "w": torch.ones(2)}, p)
    assert read_checkpoint(p, "cpu")["step"] == 3


class _Unpicklable:
    pass


def test_the_loop_s_clock_bar_and_files(tmp_path, monkeypatch, capsys):
    """On a clock that moves half a second a reading: the log's wall times, the time limit and wall_s exactly; the
    default bar on stderr; the folder made with its parents; the version in every file."""
    torch = pytest.importorskip("torch")
    import json

    from gpr3d import __version__
    from gpr3d.core import training
    from gpr3d.core.training import TrainingRun
    from tests.conftest import StepClock

    monkeypatch.setattr(training, "time", StepClock())
    model = torch.nn.Linear(2, 1, bias=False)
    opt = torch.optim.SGD(model.parameters(), lr=0.1)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0)
    out = tmp_path / "a" / "b" / "run"
    run = TrainingRun(out, model, opt, sched, steps=6, resume_key={}, config={"n": 1}, columns="step,wall_s,loss",
                      checkpoint_every=100, max_seconds=1.0)
    assert run.checkpoint == out / "checkpoint.pt" and run.step == 0 and run.wall_s == 0.0
    assert (out / "config.json").read_text() == json.dumps({"gpr3d": __version__, "n": 1}, indent=2)
    assert run.run(_batches(torch, 0, 6), _step_fn(model)) is run
    # readings: 1000 (start), then one a step (1000.5, 1001.0 ... for the row; the next for the limit)
    rows = (out / "losses.csv").read_text().splitlines()[1:]
    assert [r.split(",")[1] for r in rows] == ["0.5", "1.5"]
    assert run.step == 2 and run.wall_s == pytest.approx(2.5)  # late at step 2 (2.0 s > 1 s; at step 1 1.0 s is not)
    ck = torch.load(run.checkpoint, weights_only=True)
    assert ck["step"] == 2 and ck["gpr3d"] == __version__ and set(ck) == {
        "model", "optimizer", "scheduler", "step", "resume_key", "gpr3d"}
    err = capsys.readouterr().err  # the bar (the default), named and counted in steps
    assert "train:" in err and "2/6" in err and "step" in err
