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
