"""What every gpr3d training loop shares (the detector's, DepthNet's): the learning-rate schedule and one
optimiser step. PyTorch is imported only by the caller's objects."""

from __future__ import annotations

import math

from gpr3d.core.errors import GPR3DError

__all__ = ["warmup_cosine", "optimiser_step", "read_checkpoint"]


def warmup_cosine(warmup: int, steps: int, floor: float = 0.02):
    """Learning-rate factor of step ``k``: linear warm-up over ``warmup`` steps, then a cosine down to ``floor``."""
    def f(step: int) -> float:
        if step < warmup:
            return (step + 1) / warmup
        p = (step - warmup) / max(steps - warmup, 1)
        return floor + (1 - floor) * 0.5 * (1 + math.cos(math.pi * min(p, 1.0)))
    return f


def optimiser_step(model, opt, sched, loss, step: int, *, max_norm: float = 10.0, what: str = "training") -> None:
    """Back-propagate ``loss`` and step ``opt`` and ``sched`` (gradients clipped to ``max_norm``); a loss that is
    not finite stops the run with one line naming the step."""
    import torch

    if not torch.isfinite(loss):
        raise GPR3DError(f"{what} diverged at step {step} (loss {float(loss.detach())}); lower --lr")
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), max_norm)
    opt.step()
    sched.step()


def read_checkpoint(path, device):
    """A training checkpoint, read with ``weights_only`` (nothing that would run code is unpickled); one line
    naming the file when it cannot be read."""
    import torch

    try:
        return torch.load(path, map_location=device, weights_only=True)
    except Exception as exc:  # a checkpoint cut by a kill is never left behind (atomic), but be plain
        raise GPR3DError(f"{path}: cannot read the checkpoint ({type(exc).__name__}); delete it to restart") from None
