"""Training windows from labelled records.

A *source* is anything that maps an index to ``(Survey, labels dict)`` (labels as
written by the simulator: ``{"labels": [{"box", "apex_trace", "apex_time_s",
"visible", ...}]}``): the survey-scale synthesizer, a packed gprMax dataset, or
a user's own labelled recordings (:mod:`gpr3d.detection.userlabels`). Detection
does not depend on how the records were made.
"""

from __future__ import annotations

import numpy as np

from gpr3d.detection.windows import Window, WindowConfig, prepare, render, window_targets
from gpr3d.io.coco import PixelMap

__all__ = ["random_window", "WindowDataset", "collate"]


def random_window(survey, labels: dict, cfg: WindowConfig, rng: np.random.Generator, *, flip: bool = True,
                  target_bias: float = 0.8):
    """One training window of a record: ``(image (3, rows, traces), boxes (k, 4) px)``.

    With probability ``target_bias`` the window is placed over a labelled apex
    (anywhere in it); otherwise anywhere. ``flip`` mirrors half of the windows
    left-right (hyperbolas are symmetric).
    """
    proc = prepare(survey, cfg)
    n = proc.shape[0]
    s_per_row = (survey.n_samples - 1) * survey.dt_s / (cfg.rows - 1)
    vis = [lab for lab in labels["labels"] if lab.get("visible", True)]
    hi = max(n - cfg.traces, 0)
    if vis and rng.random() < target_bias:
        a = vis[int(rng.integers(len(vis)))]["apex_trace"]
        s0 = int(np.clip(round(a - rng.uniform(0.1, 0.9) * cfg.traces), 0, hi))
    else:
        s0 = int(rng.integers(0, hi + 1))
    block = proc[s0 : s0 + cfg.traces]
    real = block.shape[0]
    if real < cfg.traces:
        block = np.concatenate([block, np.zeros((cfg.traces - real, proc.shape[1]), np.float32)])
    scale = float(np.percentile(np.abs(proc), 99.5)) or 1.0
    win = Window(render(block, cfg.style, scale=scale),
                 PixelMap(trace0=s0 - 0.5, t0_s=-0.5 * s_per_row, s_per_px=s_per_row), s0, real)
    boxes = window_targets(labels["labels"], win)
    image = win.image
    if flip and rng.random() < 0.5:
        image = image[:, :, ::-1].copy()
        w = float(cfg.traces)
        boxes = np.stack([w - boxes[:, 2], boxes[:, 1], w - boxes[:, 0], boxes[:, 3]], axis=1).reshape(-1, 4)
    return np.ascontiguousarray(image, dtype=np.float32), boxes.astype(np.float32)


class WindowDataset:
    """A torch-style dataset of random training windows: item ``i`` draws record ``i`` of ``source``.

    ``source(i) -> (Survey, labels)``; ``n`` items per epoch; ``seed`` fixes the
    window placement, so item ``i`` is the same window every time.
    """

    def __init__(self, source, n: int, cfg: WindowConfig | None = None, *, seed: int = 0, flip: bool = True):
        self.source, self.n, self.cfg, self.seed, self.flip = source, int(n), cfg or WindowConfig(), seed, flip

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int):
        import torch

        survey, labels = self.source(int(i))
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, int(i), 77]))
        image, boxes = random_window(survey, labels, self.cfg, rng, flip=self.flip)
        target = {"boxes": torch.from_numpy(boxes), "labels": torch.ones(len(boxes), dtype=torch.int64)}
        return torch.from_numpy(image), target


def collate(batch):
    return [b[0] for b in batch], [b[1] for b in batch]
