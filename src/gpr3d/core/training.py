"""The one training engine of gpr3d (the detector's and DepthNet's runs both go through it): the learning-rate
schedule, one optimiser step, and :class:`TrainingRun`, the loop with its checkpoint, resume, log, progress bar
and time limit. PyTorch is imported only when a run starts (it is an optional dependency)."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path

from gpr3d.core.atomic import atomic_path, atomic_write_text, resume_log
from gpr3d.core.errors import GPR3DError

__all__ = ["warmup_cosine", "optimiser_step", "read_checkpoint", "TrainingRun"]


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


class TrainingRun:
    """One resumable training run in the folder ``out``, the loop every gpr3d model trains with.

    The folder holds ``checkpoint.pt`` (model, optimiser, schedule, step, the settings it was made with and what
    ``extra_state`` adds), ``losses.csv`` (one row a step, the rows after the checkpoint dropped on a resume) and
    ``config.json``. A checkpoint made with other settings is refused in one line, so two runs never mix. Every
    file is written atomically: a kill at any moment leaves the previous checkpoint whole, and running the same
    command again goes on from it.

    Parameters
    ----------
    out : str or Path
        The run's folder (made where missing).
    model, opt, sched : torch.nn.Module, torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler
        What is trained and how; their states are restored from the checkpoint when one exists.
    steps : int
        The run's length in optimiser steps.
    resume_key : dict
        The settings that must match for a checkpoint to be taken up (not the device, the output folder, ...).
    config : dict
        Written to ``config.json`` (with gpr3d's version) once the checkpoint has been checked.
    columns : str
        The log's header: ``step``, ``lr``, ``loss`` and ``wall_s`` are filled here, the other names from what
        ``step_fn`` gives back.
    checkpoint_every : int
        Steps between checkpoints (one is also written at the last step and when the time limit stops the run).
    device : str or torch.device
        Where the checkpoint's tensors are read to.
    desc : str
        The progress bar's label.
    what : str
        What diverged, in the message of a loss that is not finite.
    log : callable
        Where a resume and an early stop are told.
    progress : bool
        Show the progress bar (tqdm).
    max_seconds : float, optional
        Stop after this long (checkpoint written; running again continues).
    extra_state : callable, optional
        ``extra_state(step) -> dict``, stored in each checkpoint beside the states.

    Attributes
    ----------
    step : int
        Steps done (the checkpoint's on resuming, before :meth:`run`).
    wall_s : float
        Seconds :meth:`run` took.
    checkpoint : Path
        ``out/checkpoint.pt``.

    Raises
    ------
    GPR3DError
        A checkpoint made with other settings, or one that cannot be read.
    """

    def __init__(self, out, model, opt, sched, *, steps: int, resume_key: dict, config: dict, columns: str,
                 checkpoint_every: int, device="cpu", desc: str = "train", what: str = "training", log=print,
                 progress: bool = True, max_seconds: float | None = None, extra_state=None):
        from gpr3d import __version__

        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.model, self.opt, self.sched = model, opt, sched
        self.steps, self.key, self.every = int(steps), resume_key, int(checkpoint_every)
        self.columns = columns.split(",")
        self.desc, self.what, self.log, self.progress = desc, what, log, progress
        self.max_seconds, self.extra_state = max_seconds, extra_state
        self.version = __version__
        self.checkpoint = self.out / "checkpoint.pt"
        self.step, self.wall_s = 0, 0.0
        if self.checkpoint.exists():
            ck = read_checkpoint(self.checkpoint, device)
            if ck.get("resume_key") != resume_key:
                raise GPR3DError(f"{self.checkpoint}: made with other settings; use another --out or delete the "
                                 "checkpoint")
            model.load_state_dict(ck["model"])
            opt.load_state_dict(ck["optimizer"])
            sched.load_state_dict(ck["scheduler"])
            self.step = int(ck["step"])
            log(f"resuming from step {self.step} of {self.steps}")
        atomic_write_text(self.out / "config.json", json.dumps({"gpr3d": __version__, **config}, indent=2))

    def save(self) -> None:
        """Write the checkpoint of the step reached (atomically)."""
        import torch

        state = {"model": self.model.state_dict(), "optimizer": self.opt.state_dict(),
                 "scheduler": self.sched.state_dict(), "step": self.step, "resume_key": self.key,
                 "gpr3d": self.version, **(self.extra_state(self.step) if self.extra_state else {})}
        with atomic_path(self.checkpoint, suffix=".pt.part") as tmp:
            torch.save(state, tmp)

    def run(self, batches, step_fn) -> "TrainingRun":
        """Train from ``step`` to ``steps``: for each item of ``batches``, ``step_fn(batch)`` gives
        ``(loss, fields, postfix)`` (the loss tensor, the log's other columns as text, what the progress bar
        shows); the optimiser steps, the row is logged, the checkpoint written every ``checkpoint_every`` steps.

        Parameters
        ----------
        batches : iterable
            The batches of the steps still to do, in order (it may be longer: the run stops at ``steps``; where it
            is shorter, the last step's checkpoint is written when it runs out).
        step_fn : callable
            ``step_fn(batch) -> (loss, dict of str, dict)``.

        Returns
        -------
        TrainingRun
            ``self``, with ``step`` and ``wall_s`` set.
        """
        from tqdm import tqdm

        logf = resume_log(self.out / "losses.csv", self.step, ",".join(self.columns))
        t0 = time.perf_counter()
        bar = tqdm(total=self.steps, initial=self.step, disable=not self.progress, desc=self.desc, unit="step")
        self.model.train()
        saved = self.step
        try:
            for batch in batches:
                if self.step >= self.steps:
                    break
                loss, fields, postfix = step_fn(batch)
                optimiser_step(self.model, self.opt, self.sched, loss, self.step, what=self.what)
                self.step += 1
                row = {"step": str(self.step), "lr": f"{self.opt.param_groups[0]['lr']:.3g}",
                       "loss": f"{float(loss.detach()):.5f}", "wall_s": f"{time.perf_counter() - t0:.1f}", **fields}
                logf.write(",".join(row[c] for c in self.columns) + "\n")
                bar.update(1)
                bar.set_postfix(**postfix)
                late = self.max_seconds is not None and time.perf_counter() - t0 > self.max_seconds
                if self.step % self.every == 0 or self.step == self.steps or late:
                    logf.flush()
                    os.fsync(logf.fileno())
                    self.save()
                    saved = self.step
                if late:
                    self.log(f"stopped after {self.max_seconds:.0f} s at step {self.step}; run again to continue")
                    break
        finally:
            bar.close()
            logf.close()
        if self.step > saved:  # the batches ran out before ``steps``: the last step is kept too
            self.save()
        self.wall_s = time.perf_counter() - t0
        return self
