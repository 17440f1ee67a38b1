"""Training windows from labelled records.

A *source* is anything that maps an index to ``(Survey, labels dict)`` (labels as
written by the simulator: ``{"labels": [{"box", "apex_trace", "apex_time_s",
"visible", ...}]}``): the survey-scale synthesizer, a packed gprMax dataset, or
a user's own labelled recordings (:func:`gpr3d.io.userlabels.read_user_labels`). Detection
does not depend on how the records were made.
"""

from __future__ import annotations

import numpy as np

from gpr3d.detection.windows import WindowConfig, make_window, prepare, record_scale, rows_interval, window_targets

__all__ = ["random_window", "WindowDataset", "collate", "PackedSource", "MixedSource", "RecordsSource", "kind_labels"]


def random_window(survey, labels: dict, cfg: WindowConfig, rng: np.random.Generator, *, flip: bool = True,
                  target_bias: float = 0.8, return_kinds: bool = False, augment=None):
    """One training window of a record: ``(image (3, rows, traces), boxes (k, 4) px)``.

    With probability ``target_bias`` the window is placed over a labelled apex
    (anywhere in it); otherwise anywhere. ``flip`` mirrors half of the windows
    left-right (hyperbolas are symmetric). ``augment`` (an
    :class:`~gpr3d.detection.augment.Augment`): the record is stretched along its traces,
    its gain and noise changed first (:func:`~gpr3d.detection.augment.augment_record`).
    ``return_kinds``: a third item, the boxes' kinds.
    """
    proc = prepare(survey, cfg)
    scale = record_scale(proc)
    if augment is not None:
        from gpr3d.detection.augment import augment_record

        proc, labels, scale = augment_record(proc, labels, scale, rng, augment)
    n = proc.shape[0]
    vis = [lab for lab in labels["labels"] if lab.get("visible", True)]
    hi = max(n - cfg.traces, 0)
    if vis and rng.random() < target_bias:
        a = vis[int(rng.integers(len(vis)))]["apex_trace"]
        s0 = int(np.clip(round(a - rng.uniform(0.1, 0.9) * cfg.traces), 0, hi))
    else:
        s0 = int(rng.integers(0, hi + 1))
    win = make_window(proc, s0, cfg, rows_interval(survey, cfg), scale)
    boxes, kinds = window_targets(labels["labels"], win, return_kinds=True)
    image = win.image
    if flip and rng.random() < 0.5:
        image = image[:, :, ::-1].copy()
        w = float(cfg.traces)
        boxes = np.stack([w - boxes[:, 2], boxes[:, 1], w - boxes[:, 0], boxes[:, 3]], axis=1).reshape(-1, 4)
    out = np.ascontiguousarray(image, dtype=np.float32), boxes.astype(np.float32)
    return out + (kinds,) if return_kinds else out


def kind_labels(kinds, names) -> np.ndarray:
    """Class labels (int64) of boxes of ``kinds`` for a network naming ``names`` (``None``: all 1).

    A kind the network does not name is an error: its box would be learnt as background.
    """
    from gpr3d.core.errors import GPR3DError

    if not names:
        return np.ones(len(kinds), dtype=np.int64)
    out = []
    for k in kinds:
        if k not in names:
            raise GPR3DError(f"a label of kind {k!r}, which the detector does not name ({', '.join(names)}): "
                             "map the dataset's class names onto kinds (--class-kinds NAME=KIND)")
        out.append(names.index(k) + 1)
    return np.asarray(out, dtype=np.int64)


class WindowDataset:
    """A torch-style dataset of random training windows: item ``i`` draws record ``i`` of ``source``.

    ``source(i) -> (Survey, labels)``; ``n`` items per epoch; ``seed`` fixes the
    window placement, so item ``i`` is the same window every time.
    """

    def __init__(self, source, n: int, cfg: WindowConfig | None = None, *, seed: int = 0, flip: bool = True,
                 kinds=None, augment=None):
        self.source, self.n, self.cfg, self.seed, self.flip = source, int(n), cfg or WindowConfig(), seed, flip
        self.kinds = list(kinds) if kinds else None  #: the network's kinds (None: one class)
        self.augment = augment  #: an Augment drawn on every window, or None

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int):
        import torch

        survey, labels = self.source(int(i))
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, int(i), 77]))
        image, boxes, kinds = random_window(survey, labels, self.cfg, rng, flip=self.flip, return_kinds=True,
                                            augment=self.augment)
        target = {"boxes": torch.from_numpy(boxes), "labels": torch.from_numpy(kind_labels(kinds, self.kinds))}
        return torch.from_numpy(image), target


def collate(batch):
    return [b[0] for b in batch], [b[1] for b in batch]


class PackedSource:
    """Records of packed labelled datasets (:class:`gpr3d.io.packed.PackedDataset`), the last ``holdout`` of each left out.

    ``path``: one file or a list; an item ``"FILE:N"`` holds out the last ``N`` records of
    that file instead of ``holdout``. ``source(i)`` cycles through all kept records.
    """

    def __init__(self, path, *, holdout: int = 0):
        from gpr3d.core.errors import GPR3DError
        from gpr3d.io.packed import PackedDataset

        items = [path] if isinstance(path, (str, bytes)) or not hasattr(path, "__iter__") else list(path)
        self.parts = []
        for item in items:
            name, keep_out = str(item), holdout
            head, sep, tail = name.rpartition(":")
            if sep and tail.isdigit():
                name, keep_out = head, int(tail)
            ds = PackedDataset(name)
            n = len(ds) - keep_out
            if n < 1:
                raise GPR3DError(f"{name}: {len(ds)} records; none left after holding out {keep_out}")
            self.parts.append((ds, n))
        self.n = sum(n for _, n in self.parts)

    def __call__(self, i: int):
        i = int(i) % self.n
        for ds, n in self.parts:
            if i < n:
                return ds[i]
            i -= n
        raise AssertionError("unreachable")  # pragma: no cover


class RecordsSource:
    """Records held in memory (e.g. a user's labelled B-scans); ``source(i)`` cycles through them."""

    def __init__(self, records):
        from gpr3d.core.errors import GPR3DError

        self.records = list(records)
        if not self.records:
            raise GPR3DError("no labelled records to train on")
        self.n_boxes = sum(len(lab["labels"]) for _, lab in self.records)
        if self.n_boxes == 0:
            raise GPR3DError("the labelled records hold no boxes: nothing to learn from")

    def __call__(self, i: int):
        return self.records[int(i) % len(self.records)]


class MixedSource:
    """``source(i)`` from ``second`` for a seeded ``fraction`` of the indices, else from ``first``.

    Each index's draw is seeded by ``(i, salt)``: a mix nested in another must have a salt
    of its own, or its draw repeats the outer one's and it never picks ``second`` where the
    outer mix handed it the index (with ``fraction`` below the outer one's)."""

    def __init__(self, first, second, fraction: float, *, salt: int = 0x313):
        self.first, self.second, self.fraction, self.salt = first, second, float(fraction), int(salt)
        inner, stack = set(), [first, second]
        while stack:  # the salts of every mix inside this one
            m = stack.pop()
            if isinstance(m, MixedSource):
                inner.add(m.salt)
                stack += [m.first, m.second]
        if self.salt in inner:
            raise ValueError(f"a mix nested in another needs a salt of its own (both {self.salt:#x}): it would "
                             "never pick its second source")

    def __call__(self, i: int):
        u = np.random.default_rng(np.random.SeedSequence([int(i), self.salt])).random()
        return self.second(i) if u < self.fraction else self.first(i)
