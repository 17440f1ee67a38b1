"""Training a detector: seeded, checkpointed every few steps, resumable after a kill.

``OUT/checkpoint.pt`` holds the model, the optimiser, the learning-rate schedule,
the step (and epoch) and the configuration; ``OUT/losses.csv`` logs every loss
term; ``OUT/config.json`` the configuration and gpr3d version. Running the same
training again continues from the checkpoint (a different configuration is
refused, so two runs never mix). At the end the weights are exported with
:func:`gpr3d.detection.weights.save_weights`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

from gpr3d.core.deps import require
from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.core.training import TrainingRun, warmup_cosine
from gpr3d.detection.models import MODELS, resolve_device
from gpr3d.detection.windows import WindowConfig

__all__ = ["TrainConfig", "OPTIMISERS", "train_detector"]

#: "adamw" (default here: trains from scratch fastest), "sgd" (torchvision's detection recipe),
#: "reference" (the paper's DepthNet optimiser: SGD lr 4e-5, momentum 0.9, weight decay 5e-5)
OPTIMISERS = ("adamw", "sgd", "reference")


@dataclass
class TrainConfig:
    """What ``gpr3d train detector`` runs."""

    out: str
    model: str = "frcnn_lean"
    steps: int = 3000
    batch: int = 8
    lr: float | None = None  #: None: the optimiser's default (adamw 1e-3, sgd 0.02, reference 4e-5)
    optimiser: str = "adamw"
    weight_decay: float | None = None
    warmup: int = 200
    seed: int = 0
    data_seed: int = 1000  #: records are survey_sample(data_seed, i): keep it away from the test seeds
    device: str = "cpu"
    workers: int = 0  #: data-loading processes
    checkpoint_every: int = 100
    window: dict = field(default_factory=lambda: WindowConfig().to_dict())
    init: str | None = None  #: weights file to start from (fine-tuning) instead of a fresh model
    #: packed labelled datasets mixed into the records: a file or a list, each "FILE" or "FILE:N" (N held out)
    packed: str | list | None = None
    packed_fraction: float = 0.2  #: share of the windows drawn from ``packed``
    packed_holdout: int = 60  #: the last records of each, kept out of training (the evaluation uses them)
    labels: str | None = None  #: the user's own labelled B-scans (COCO .json, VOC .xml or folder) mixed in
    labels_fraction: float = 0.5  #: share of the windows drawn from ``labels``
    pixel_map: str | None = None  #: time axis of labelled pictures (screenshots): "s_per_px=...,t0_s=..."
    labels_names: list | None = None  #: YOLO class names in id order (when the dataset has no data.yaml)
    labels_kinds: str | None = None  #: class name -> target kind, "pipe=pvc_pipe,steel=rebar"
    labels_frequency_hz: float | None = None  #: the labelled pictures' antenna frequency
    labels_pattern: str | None = None  #: YOLO pictures whose name matches this glob only (e.g. one radar's)
    #: target kinds the detector names (None: one class, or those of --init); a one-class --init is widened
    kinds: list | None = None
    freeze: int = 0  #: backbone stages kept fixed: 0 none, 1 the stem, 2 the stem and layer1, ...
    #: training windows stretched along the traces, their gain and noise changed (gpr3d.detection.augment):
    #: None: none; True: the default ranges; a dict: Augment's fields
    augment: dict | bool | None = None
    #: share of the synthetic records drawn from the ``wall_source`` given to :func:`train_detector` (handheld
    #: concrete wall scans, ``SurveySource(data_seed, profile="wall")`` in ``gpr3d train detector``)
    wall_fraction: float = 0.0
    #: the wall records' box time pad in periods (``SurveySource(..., box_pad=)``; None: the label rule's 0.7)
    wall_box_pad: float | None = None
    #: that pad in periods of each wall record's drawn wavelet (``SurveySource(..., pad_wavelet=True)``)
    wall_pad_wavelet: bool = False

    def __post_init__(self):
        if self.model not in MODELS:
            raise InvalidDataError(f"unknown detector {self.model!r}; choose one of {', '.join(MODELS)}")
        if self.optimiser not in OPTIMISERS:
            raise InvalidDataError(f"unknown optimiser {self.optimiser!r}; choose one of {', '.join(OPTIMISERS)}")
        for name, low in (("steps", 1), ("batch", 2), ("checkpoint_every", 1), ("warmup", 1), ("seed", 0),
                          ("data_seed", 0)):
            v = getattr(self, name)
            if not isinstance(v, int) or v < low:
                raise InvalidDataError(f"--{name.replace('_', '-')} must be an integer >= {low}, got {v!r}"
                                       + (" (batch norm needs two windows a step)" if name == "batch" else ""))
        if not isinstance(self.workers, int) or self.workers < 0:
            raise InvalidDataError(f"--workers must be 0 or more, got {self.workers!r}")
        if self.lr is not None and not (0 < self.lr < 10):
            raise InvalidDataError(f"--lr must lie in (0, 10), got {self.lr!r}")
        WindowConfig(**self.window)
        if not 0.0 <= self.packed_fraction <= 1.0:
            raise InvalidDataError(f"--packed-fraction must lie in 0..1, got {self.packed_fraction!r}")
        if not isinstance(self.packed_holdout, int) or self.packed_holdout < 0:
            raise InvalidDataError(f"--packed-holdout must be 0 or more, got {self.packed_holdout!r}")
        if not 0.0 <= self.labels_fraction <= 1.0:
            raise InvalidDataError(f"--labels-fraction must lie in 0..1, got {self.labels_fraction!r}")
        if not 0.0 <= self.wall_fraction <= 1.0:
            raise InvalidDataError(f"--wall-fraction must lie in 0..1, got {self.wall_fraction!r}")
        if self.wall_box_pad is not None and not (isinstance(self.wall_box_pad, (int, float))
                                                  and math.isfinite(self.wall_box_pad) and 0 <= self.wall_box_pad <= 2):
            raise InvalidDataError(f"--wall-box-pad must lie in 0..2 periods, got {self.wall_box_pad!r}")
        if self.wall_box_pad is not None and not self.wall_fraction:
            raise InvalidDataError("--wall-box-pad sets the wall records' boxes: give --wall-fraction too")
        if self.wall_pad_wavelet not in (True, False):
            raise InvalidDataError(f"--wall-pad-wavelet is true or false, got {self.wall_pad_wavelet!r}")
        if self.wall_pad_wavelet and not self.wall_fraction:
            raise InvalidDataError("--wall-pad-wavelet sets the wall records' boxes: give --wall-fraction too")
        if not isinstance(self.freeze, int) or not 0 <= self.freeze <= 4:
            raise InvalidDataError(f"--freeze must be an integer in 0..4 (backbone stages kept fixed), got {self.freeze!r}")
        if self.kinds is not None:
            from gpr3d.io.coco import CATEGORIES

            self.kinds = list(self.kinds)
            bad = [k for k in self.kinds if k not in CATEGORIES]
            if bad or not self.kinds or len(set(self.kinds)) != len(self.kinds):
                raise InvalidDataError(f"--kinds must name distinct target kinds ({', '.join(CATEGORIES)}), "
                                       f"got {self.kinds!r}")
        if self.augment is True:
            from gpr3d.detection.augment import Augment

            self.augment = Augment().to_dict()
        elif isinstance(self.augment, dict):
            from gpr3d.detection.augment import Augment

            try:
                self.augment = Augment(**self.augment).to_dict()
            except TypeError:
                raise InvalidDataError(f"--augment takes stretch, gain and noise, got {sorted(self.augment)}") from None
        elif self.augment not in (None, False):
            raise InvalidDataError(f"--augment must be on, off or a dict of ranges, got {self.augment!r}")
        else:
            self.augment = None
        if self.init == "default":
            from gpr3d.detection.weights import DEFAULT_WEIGHTS

            self.init = str(DEFAULT_WEIGHTS)

    def resolved_lr(self) -> float:
        return self.lr or {"adamw": 1e-3, "sgd": 0.02, "reference": 4e-5}[self.optimiser]


def _optimiser(cfg: TrainConfig, params):
    torch = require("torch")
    lr = cfg.resolved_lr()
    if cfg.optimiser == "adamw":
        return torch.optim.AdamW(params, lr=lr, weight_decay=1e-4 if cfg.weight_decay is None else cfg.weight_decay)
    wd = {"sgd": 1e-4, "reference": 5e-5}[cfg.optimiser] if cfg.weight_decay is None else cfg.weight_decay
    return torch.optim.SGD(params, lr=lr, momentum=0.9, weight_decay=wd)


def _freeze(model, stages: int) -> None:
    """Keep the first ``stages`` backbone stages of a ResNet-FPN model fixed (1: the stem, 2: with layer1, ...)."""
    if not stages:
        return
    body = getattr(getattr(model, "backbone", None), "body", None)
    if body is None or not hasattr(body, "conv1"):
        raise GPR3DError("--freeze needs a ResNet backbone (a frcnn_*, retinanet_r18 or fcos_r18 model)")
    parts = [["conv1", "bn1"], ["layer1"], ["layer2"], ["layer3"]][:stages]
    for name in (n for group in parts for n in group):
        mod = getattr(body, name, None)
        if mod is None:
            raise GPR3DError(f"--freeze {stages}: the backbone has no {name}")
        for p in mod.parameters():
            p.requires_grad_(False)


def train_detector(cfg: TrainConfig, source, *, wall_source=None, progress: bool = True, log=print,
                   max_seconds: float | None = None) -> dict:
    """Train ``cfg.model`` on windows of ``source(i) -> (Survey, labels)``; returns a summary.

    ``wall_source`` gives ``cfg.wall_fraction`` of the synthetic records (mixed in first, with a draw of its
    own, so packed records and labels are mixed around it as without it). Resumes from ``cfg.out/checkpoint.pt``
    when it exists for the same configuration; ``max_seconds`` stops early (checkpoint saved; running again
    continues).
    """
    if cfg.wall_fraction and wall_source is None:
        raise GPR3DError(f"--wall-fraction {cfg.wall_fraction}: no wall-scan source was given to draw them from")
    if cfg.wall_fraction and getattr(wall_source, "box_pad", None) != cfg.wall_box_pad:
        raise GPR3DError(f"--wall-box-pad {cfg.wall_box_pad}: the wall-scan source given pads its boxes by "
                         f"{getattr(wall_source, 'box_pad', None)}")
    if cfg.wall_fraction and bool(getattr(wall_source, "pad_wavelet", False)) != cfg.wall_pad_wavelet:
        raise GPR3DError(f"--wall-pad-wavelet {cfg.wall_pad_wavelet}: the wall-scan source given pads by "
                         f"{'the drawn wavelet' if cfg.wall_pad_wavelet is False else 'the label'}'s frequency")
    torch = require("torch")

    from gpr3d.detection.data import WindowDataset, collate
    from gpr3d.detection.models import build_model, count_parameters

    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(cfg.device)
    cfg_dict = asdict(cfg)
    same = {k: v for k, v in cfg_dict.items() if k not in ("device", "workers", "checkpoint_every", "out")}
    if not cfg.wall_fraction:  # (runs from before the setting resume)
        del same["wall_fraction"]
    if cfg.wall_box_pad is None:  # (likewise)
        del same["wall_box_pad"]
    if not cfg.wall_pad_wavelet:
        del same["wall_pad_wavelet"]
    torch.manual_seed(cfg.seed)
    kinds = cfg.kinds
    init = None
    if cfg.init:
        from gpr3d.detection.weights import load_weights

        init, init_window, _ = load_weights(cfg.init)
        init_kinds = getattr(init, "gpr3d_kinds", None)
        kinds = kinds if kinds is not None else init_kinds
        if init_window.to_dict() != cfg.window:
            raise GPR3DError(f"--init {cfg.init}: made for another model or window; it cannot start {cfg.model!r}")
        if init_kinds and not set(kinds) <= set(init_kinds):
            raise GPR3DError(f"--init {cfg.init}: names {', '.join(init_kinds)}; it cannot start "
                             f"{', '.join(k for k in kinds if k not in init_kinds)}")
    model = build_model(cfg.model, image_size=cfg.window["rows"], kinds=kinds)
    if init is not None:
        if type(init) is not type(model):
            raise GPR3DError(f"--init {cfg.init}: made for another model or window; it cannot start {cfg.model!r}")
        state = init.state_dict()
        init_kinds = getattr(init, "gpr3d_kinds", None)
        if kinds and init_kinds != kinds:
            from gpr3d.detection.models import widen_to_kinds

            try:
                state = widen_to_kinds(state, kinds, from_kinds=init_kinds)
            except KeyError:
                raise GPR3DError(f"--init {cfg.init}: only a Faster R-CNN can be given kinds") from None
        try:
            model.load_state_dict(state)
        except RuntimeError:
            raise GPR3DError(f"--init {cfg.init}: its weights do not fit {cfg.model!r}") from None
    model.gpr3d_kinds = kinds
    _freeze(model, cfg.freeze)
    model = model.to(device)
    if cfg.wall_fraction:
        from gpr3d.detection.data import MixedSource

        source = MixedSource(source, wall_source, cfg.wall_fraction, salt=0x315)
    if cfg.packed:
        from gpr3d.detection.data import MixedSource, PackedSource

        # (with labels too the packed mix lies inside theirs: a draw of its own, else it never picks a packed record)
        source = MixedSource(source, PackedSource(cfg.packed, holdout=cfg.packed_holdout), cfg.packed_fraction,
                             **({"salt": 0x314} if cfg.labels else {}))
    if cfg.labels:
        from gpr3d.detection.data import MixedSource, RecordsSource
        from gpr3d.io.labelled import read_labelled

        user = RecordsSource(read_labelled(cfg.labels, pixel_map=cfg.pixel_map, names=cfg.labels_names,
                                           kinds=cfg.labels_kinds, frequency_hz=cfg.labels_frequency_hz,
                                           pattern=cfg.labels_pattern))
        log(f"{len(user.records)} labelled record(s), {user.n_boxes} box(es) from {cfg.labels}: "
            f"{cfg.labels_fraction:.0%} of the windows")
        source = MixedSource(source, user, cfg.labels_fraction)
    opt = _optimiser(cfg, [p for p in model.parameters() if p.requires_grad])
    sched = torch.optim.lr_scheduler.LambdaLR(opt, warmup_cosine(cfg.warmup, cfg.steps))
    # records are drawn fresh and never repeat: the run is one epoch of steps * batch windows
    run = TrainingRun(out, model, opt, sched, steps=cfg.steps, resume_key=same, config={"config": cfg_dict},
                      columns="step,lr,loss,wall_s,terms", checkpoint_every=cfg.checkpoint_every, device=device,
                      desc=f"train {cfg.model}", log=log, progress=progress, max_seconds=max_seconds,
                      extra_state=lambda k: {"epoch": 0, "windows_seen": k * cfg.batch, "config": cfg_dict})
    augment = None
    if cfg.augment:
        from gpr3d.detection.augment import Augment

        augment = Augment(**cfg.augment)
    ds = WindowDataset(source, cfg.steps * cfg.batch, WindowConfig(**cfg.window), seed=cfg.data_seed, kinds=kinds,
                       augment=augment)
    # item k of the whole run is drawn in order; resuming skips what was already seen
    sampler = list(range(run.step * cfg.batch, cfg.steps * cfg.batch))
    loader = torch.utils.data.DataLoader(ds, batch_size=cfg.batch, sampler=sampler, collate_fn=collate,
                                         num_workers=cfg.workers, persistent_workers=False)

    def step_fn(batch):
        images, targets = batch
        images = [im.to(device, non_blocking=True) for im in images]
        targets = [{k: v.to(device) for k, v in t.items()} for t in targets]
        losses = model(images, targets)
        loss = sum(losses.values())
        terms = ";".join(f"{k}={float(v.detach()):.5f}" for k, v in losses.items())
        return loss, {"terms": terms}, {"loss": f"{float(loss.detach()):.3f}"}

    run.run(loader, step_fn)
    return {"steps": run.step, "wall_s": run.wall_s, "parameters": count_parameters(model), "model": model,
            "kinds": kinds, "checkpoint": str(run.checkpoint)}
