"""DepthNet: the host's permittivity and every target's depth from the B-scan, learnt.

As in the reference, a ResNet encoder reads a 224 x 224 window of the B-scan; its
pooled features give the host's relative permittivity ``eps_r``; fully connected
sub-nets take each detected box with its RoI features (RoIAlign on the encoder's
third stage) and give the depth of that target's top. Loss:
``lambda_eps * MSE(eps) + lambda_d * MSE(depth)``.

**Windows drawn to a physical scale.** A hyperbola's shape tells ``eps_r`` only
when the picture's aspect is known, and records differ in trace spacing (2 mm to
10 cm) and time window (5 to 100 ns). So each window spans the record's whole
time window ``T`` in its rows and ``alpha * D`` metres of profile in its columns,
centred on a target, where ``D = c * T / 2`` is the window's depth in vacuum: the
asymptotes of every hyperbola then have the slope ``alpha * sqrt(eps_r)`` in the
picture, whatever the radar, and depths are learnt as fractions ``depth / D``.
Trace positions come from the file (wheel, GPS) or a given spacing
(:func:`gpr3d.inversion.hyperbola.trace_positions`); the columns are sampled from
the traces (box-filtered first where several traces fall in one column).
The rows are the processing every network sees (:func:`gpr3d.processing.image.network_view`).
Time zero is not given to the network; it sees the direct wave's peak time as a
fraction of ``T`` (:func:`gpr3d.inversion.hyperbola.direct_wave_time`), from the data.

Encoders (``ARCHS``): ``"resnet10n"`` (the default: four stages of one basic block,
``width``-``8 * width`` channels: about a million parameters, trains on CPU) and
torchvision's ``resnet18/34/50/101`` (the reference uses ResNet-101), all built
with ``weights=None``.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from gpr3d.core.atomic import atomic_path
from gpr3d.core.deps import require, resolve_device
from gpr3d.core.errors import FormatError, GPR3DError, InvalidDataError
from gpr3d.core.training import TrainingRun, warmup_cosine
from gpr3d.core.units import C0
from gpr3d.io.weights import half_state_dict, read_weights_file

__all__ = ["ARCHS", "DepthConfig", "DepthRecord", "prepare_depth_record", "depth_window", "window_targets_m", "crop_time",
           "build_depthnet", "DepthTrainConfig", "train_depthnet", "save_depthnet", "load_depthnet",
           "DepthEstimator", "DEFAULT_DEPTHNET", "cache_depth_records", "load_depth_records", "export_depthnet_onnx",
           "validate_depthnet"]

ARCHS = ("resnet10n", "resnet18", "resnet34", "resnet50", "resnet101")
FORMAT = "gpr3d.depthnet"
DEFAULT_DEPTHNET = Path(__file__).with_name("default_depthnet.onnx")
EPS_CLAMP = (1.0, 81.0)


@dataclass
class DepthConfig:
    """The network and its windows."""

    arch: str = "resnet10n"
    width: int = 24  #: channels of the first stage of ``resnet10n`` (then x2, x4, x8)
    size: int = 224  #: window pixels (rows and columns)
    alpha: float = 0.5  #: window width in units of the window's vacuum depth c*T/2

    def __post_init__(self):
        if self.arch not in ARCHS:
            raise InvalidDataError(f"unknown DepthNet encoder {self.arch!r}; choose one of {', '.join(ARCHS)}")
        if not (isinstance(self.width, int) and 8 <= self.width <= 128):
            raise InvalidDataError(f"DepthNet width must be an integer in 8..128, got {self.width!r}")
        if not (isinstance(self.size, int) and 64 <= self.size <= 1024 and self.size % 32 == 0):
            raise InvalidDataError(f"DepthNet window size must be a multiple of 32 in 64..1024, got {self.size!r}")
        if not (0.05 <= float(self.alpha) <= 5.0):
            raise InvalidDataError(f"DepthNet alpha must lie in 0.05..5, got {self.alpha!r}")


# ---------------------------------------------------------------------------------------------------- records

@dataclass
class DepthRecord:
    """A record made ready for DepthNet windows (small: ``size`` rows per trace)."""

    proc: np.ndarray  #: (n_traces, size) float32, the detector's processing
    x_m: np.ndarray  #: trace positions along the profile (m), increasing
    window_s: float  #: time of the last row (s from the first sample)
    direct_frac: float  #: the direct wave's envelope peak, as a fraction of window_s
    scale: float  #: amplitude every window of this record is normalised by
    offset_m: float = 0.0
    dt_s: float = 0.0  #: the record's own sample interval
    eps_r: float = float("nan")  #: truth, when known (training)
    labels: list = field(default_factory=list)  #: visible labels (truth, training)

    @property
    def depth_scale_m(self) -> float:
        """``D = c * T / 2``: the window's depth in vacuum."""
        return C0 * self.window_s / 2

    @property
    def s_per_row(self) -> float:
        return self.window_s / (self.proc.shape[1] - 1)

    def x_of_trace(self, trace):
        return np.interp(trace, np.arange(self.x_m.size), self.x_m)


def prepare_depth_record(survey, labels: dict | None = None, *, size: int = 224,
                         trace_spacing_m: float | None = None) -> DepthRecord:
    """A :class:`DepthRecord` of ``survey`` (labels: the simulator's dict, for training)."""
    from gpr3d.inversion.hyperbola import direct_wave_time, trace_positions
    from gpr3d.processing.image import network_view, record_scale

    proc = network_view(survey, size)
    x = np.asarray(trace_positions(survey, trace_spacing_m), dtype=np.float64)
    x = x - x[0]
    x = x + np.arange(x.size) * 1e-9  # strictly increasing (a cart standing still repeats positions)
    window = (survey.n_samples - 1) * survey.dt_s
    dw, _ = direct_wave_time(survey)
    vis = [dict(lab) for lab in (labels or {}).get("labels", []) if lab.get("visible", True)]
    return DepthRecord(proc=proc, x_m=x, window_s=float(window), direct_frac=float(dw / window),
                       scale=record_scale(proc), offset_m=float(survey.offset_m or 0.0), dt_s=float(survey.dt_s),
                       eps_r=float((labels or {}).get("eps_r", float("nan"))), labels=vis)


def _columns(rec: DepthRecord, left_m: float, width_m: float, size: int, smoothed: np.ndarray) -> np.ndarray:
    xc = left_m + (np.arange(size) + 0.5) * width_m / size
    fi = np.interp(xc, rec.x_m, np.arange(rec.x_m.size, dtype=np.float64))
    i0 = np.clip(np.floor(fi).astype(int), 0, rec.x_m.size - 1)
    i1 = np.minimum(i0 + 1, rec.x_m.size - 1)
    w = (fi - i0)[:, None]
    block = (1 - w) * smoothed[i0] + w * smoothed[i1]
    half = 0.5 * _interval(rec)
    outside = (xc < rec.x_m[0] - half) | (xc > rec.x_m[-1] + half)
    block[outside] = 0.0
    return block.astype(np.float32)


def _interval(rec: DepthRecord) -> float:
    """The record's mean trace interval (m; 0 for one trace): its length over its intervals. Not the median: a cart
    that stood still for most of a record (positions from a few GPS fixes) repeats one position, so the median
    interval is nil."""
    return float(rec.x_m[-1] - rec.x_m[0]) / (rec.x_m.size - 1) if rec.x_m.size > 1 else 0.0


def _smoothed(rec: DepthRecord, width_m: float, size: int) -> np.ndarray:
    """The traces box-filtered to the column width where several traces share a column (anti-aliasing); a column
    wider than the record averages it all (a centred filter of its trace count, the next odd one)."""
    from gpr3d.processing.analytic import running_mean

    if rec.x_m.size < 2:
        return rec.proc
    per = min((width_m / size) / max(_interval(rec), 1e-9), rec.x_m.size | 1)
    return running_mean(rec.proc, int(round(per)), axis=0) if per > 1.5 else rec.proc


def depth_window(rec: DepthRecord, centre_m: float, cfg: DepthConfig, *, smoothed: np.ndarray | None = None):
    """The window centred at ``centre_m`` along the profile: ``(image (3, size, size) float32, left_m, width_m)``."""
    from gpr3d.processing.image import render_channels

    width = cfg.alpha * rec.depth_scale_m
    left = centre_m - width / 2
    sm = _smoothed(rec, width, cfg.size) if smoothed is None else smoothed
    block = _columns(rec, left, width, cfg.size, sm)
    return render_channels(block, "channels", scale=rec.scale), left, width


def box_to_window(rec: DepthRecord, box, left_m: float, width_m: float, size: int) -> list[float]:
    """A record box ``[trace_start, t_start_s, trace_end, t_end_s]`` in window pixels ``[x0, y0, x1, y1]``."""
    x0, x1 = rec.x_of_trace(float(box[0])), rec.x_of_trace(float(box[2]))
    spr = rec.s_per_row
    return [(x0 - left_m) / width_m * size, float(box[1]) / spr + 0.5, (x1 - left_m) / width_m * size,
            float(box[3]) / spr + 0.5]


def window_targets_m(rec: DepthRecord, left_m: float, width_m: float, size: int):
    """Labelled targets whose apex lies in the window: ``(boxes (k, 4) px, depth fractions (k,))``."""
    boxes, q = [], []
    for lab in rec.labels:
        ax = (rec.x_of_trace(lab["apex_trace"]) - left_m) / width_m * size
        if not 0 <= ax <= size:
            continue
        b = box_to_window(rec, lab["box"], left_m, width_m, size)
        b = [max(b[0], 0.0), max(b[1], 0.0), min(b[2], float(size)), min(b[3], float(size))]
        if b[2] - b[0] < 1 or b[3] - b[1] < 1:
            continue
        boxes.append(b)
        q.append(float(lab["depth_m"]) / rec.depth_scale_m)
    return np.asarray(boxes, np.float32).reshape(-1, 4), np.asarray(q, np.float32)


def cache_depth_records(source, indices, folder, *, size: int = 224, log=print) -> Path:
    """Prepare records ``source(i)`` into ``folder/rec_NNNNNN.npz`` (atomic; the ones there are kept: resumable)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    done = 0
    for i in indices:
        path = folder / f"rec_{int(i):06d}.npz"
        if path.exists():
            continue
        survey, labels = source(int(i))
        rec = prepare_depth_record(survey, labels, size=size)
        meta = {k: getattr(rec, k) for k in ("window_s", "direct_frac", "scale", "offset_m", "dt_s", "eps_r")}
        with atomic_path(path, suffix=".npz.part") as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, proc=rec.proc.astype(np.float16), x_m=rec.x_m,
                         meta=json.dumps(meta), labels=json.dumps(rec.labels))
        done += 1
        if done % 50 == 0:
            log(f"{done} records prepared in {folder}")
    return folder


def load_depth_records(folder) -> list[DepthRecord]:
    out = []
    for path in sorted(Path(folder).glob("rec_*.npz")):
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            out.append(DepthRecord(proc=z["proc"].astype(np.float32), x_m=z["x_m"], labels=json.loads(str(z["labels"])),
                                   **meta))
    return out


# ---------------------------------------------------------------------------------------------------- model

def build_depthnet(cfg: DepthConfig | None = None):
    """The network (torch ``nn.Module``): ``forward(images, boxes) -> (eps (B,), [depth fractions (k_i,)])``."""
    torch = require("torch")
    nn = torch.nn
    from torchvision.ops import roi_align

    cfg = cfg or DepthConfig()

    def encoder():
        if cfg.arch == "resnet10n":
            from torchvision.models.resnet import BasicBlock

            w = cfg.width

            def stage(cin, cout, stride):
                down = None if stride == 1 and cin == cout else nn.Sequential(
                    nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))
                return BasicBlock(cin, cout, stride, down)

            stem = nn.Sequential(nn.Conv2d(3, w, 7, 2, 3, bias=False), nn.BatchNorm2d(w), nn.ReLU(inplace=True),
                                 nn.MaxPool2d(3, 2, 1))
            return stem, stage(w, w, 1), stage(w, 2 * w, 2), stage(2 * w, 4 * w, 2), stage(4 * w, 8 * w, 2), 4 * w, 8 * w
        import torchvision.models as tvm

        m = getattr(tvm, cfg.arch)(weights=None)
        stem = nn.Sequential(m.conv1, m.bn1, m.relu, m.maxpool)
        c3 = m.layer3[-1].conv3.out_channels if hasattr(m.layer3[-1], "conv3") else m.layer3[-1].conv2.out_channels
        c4 = m.layer4[-1].conv3.out_channels if hasattr(m.layer4[-1], "conv3") else m.layer4[-1].conv2.out_channels
        return stem, m.layer1, m.layer2, m.layer3, m.layer4, c3, c4

    class DepthNet(nn.Module):
        def __init__(self):
            super().__init__()
            self.stem, self.layer1, self.layer2, self.layer3, self.layer4, c3, c4 = encoder()
            self.eps_head = nn.Sequential(nn.Linear(c4 + 1, 64), nn.ReLU(inplace=True), nn.Linear(64, 1))
            self.roi_reduce = nn.Sequential(nn.Conv2d(c3, 16, 1), nn.ReLU(inplace=True))
            self.roi_fc = nn.Sequential(nn.Linear(16 * 7 * 7, 64), nn.ReLU(inplace=True))
            # the box (4), the direct wave (1), 1/sqrt(eps) and the box top over sqrt(eps) (2)
            self.depth_head = nn.Sequential(nn.Linear(64 + 7, 64), nn.ReLU(inplace=True), nn.Linear(64, 1))
            self.register_buffer("mean", torch.tensor([0.5, 0.5, 0.5]).view(1, 3, 1, 1))
            self.size = cfg.size

        def forward(self, images, rois, direct):
            """``images (B, 3, S, S)``, ``rois (K, 5)`` = [window index, x0, y0, x1, y1] in pixels,
            ``direct (B,)`` fractions -> ``eps (B,)``, depth fractions ``(K,)``."""
            x = (images - self.mean) / 0.25
            f3 = self.layer3(self.layer2(self.layer1(self.stem(x))))
            f4 = self.layer4(f3)
            g = torch.cat([f4.mean(dim=(2, 3)), direct[:, None]], dim=1)
            log_eps = self.eps_head(g)[:, 0] + math.log(8.0)
            eps = torch.exp(log_eps.clamp(math.log(EPS_CLAMP[0]), math.log(EPS_CLAMP[1])))
            feats = roi_align(f3, rois, output_size=7, spatial_scale=1.0 / 16, sampling_ratio=2, aligned=True)
            r = self.roi_fc(self.roi_reduce(feats).flatten(1))
            idx = rois[:, 0].long()
            bx = rois[:, 1:] / self.size
            d = direct[idx]
            s = eps.detach()[idx].rsqrt()
            extra = torch.cat([bx, d[:, None], s[:, None], ((bx[:, 1] - d) * s)[:, None]], dim=1)
            q = self.depth_head(torch.cat([r, extra], dim=1))[:, 0] + (bx[:, 1] - d) * s
            return eps, q

    return DepthNet()


def _rois(boxes) -> np.ndarray:
    """Per-window box lists -> ``(K + 1, 5)`` RoIs; the last one is a whole-window dummy (no box is no shape)."""
    rows = [[k, *b] for k, bb in enumerate(boxes) for b in np.asarray(bb, np.float32).reshape(-1, 4)]
    return np.asarray(rows + [[0, 0, 0, 1, 1]], np.float32).reshape(-1, 5)


def _split(q: np.ndarray, boxes) -> list:
    n = [len(np.asarray(b).reshape(-1, 4)) for b in boxes]
    return list(np.split(q[: sum(n)], np.cumsum(n)[:-1]))


# ---------------------------------------------------------------------------------------------------- training

#: "adamw" (the default: trains best here), "reference" (the paper's: SGD lr 4e-5, momentum 0.9, weight decay 5e-5)
OPTIMISERS = ("adamw", "reference")


@dataclass
class DepthTrainConfig:
    """What ``gpr3d train depthnet`` runs."""

    out: str
    steps: int = 1500
    batch: int = 16
    lr: float | None = None
    optimiser: str = "adamw"
    lambda_eps: float = 1.0
    lambda_depth: float = 1.0
    seed: int = 0
    device: str = "cpu"
    checkpoint_every: int = 100
    net: dict = field(default_factory=lambda: asdict(DepthConfig()))
    init: str | None = None  #: a DepthNet .pt to start from (continued training, fine-tuning) instead of a fresh net

    def __post_init__(self):
        if self.optimiser not in OPTIMISERS:
            raise InvalidDataError(f"unknown optimiser {self.optimiser!r}; choose one of {', '.join(OPTIMISERS)}")
        for name, low in (("steps", 1), ("batch", 2), ("checkpoint_every", 1), ("seed", 0)):
            v = getattr(self, name)
            if not isinstance(v, int) or v < low:
                raise InvalidDataError(f"--{name.replace('_', '-')} must be an integer >= {low}, got {v!r}")
        if self.lr is not None and not (0 < self.lr < 10):
            raise InvalidDataError(f"--lr must lie in (0, 10), got {self.lr!r}")
        for name in ("lambda_eps", "lambda_depth"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InvalidDataError(f"--{name.replace('_', '-')} must be a number >= 0, got {v!r}")
        DepthConfig(**self.net)


def crop_time(rec: DepthRecord, fraction: float) -> DepthRecord:
    """The record as if its time window had been ``fraction`` of what it is (rows resampled; labels kept
    whose apex lies inside, their boxes as they were: the window clips them)."""
    from gpr3d.processing.image import resample_rows

    size = rec.proc.shape[1]
    last = max(int(round(fraction * (size - 1))), 8)
    window = rec.window_s * last / (size - 1)
    labels = [lab for lab in rec.labels if lab["apex_time_s"] < window]
    return DepthRecord(proc=resample_rows(rec.proc[:, : last + 1], size), x_m=rec.x_m, window_s=window,
                       direct_frac=rec.direct_frac * rec.window_s / window, scale=rec.scale, offset_m=rec.offset_m,
                       dt_s=rec.dt_s, eps_r=rec.eps_r, labels=labels)


def _training_item(rec: DepthRecord, cfg: DepthConfig, rng: np.random.Generator, smoothed=None):
    """A random window over one of the record's labelled targets (or anywhere), mirrored half the time.

    Half the windows come from the record cut to a shorter time window (35-100 %, past the direct
    wave): recordings differ in how much of their window the targets and the direct wave take.
    """
    if rng.random() < 0.5:
        rec = crop_time(rec, rng.uniform(max(0.35, min(rec.direct_frac + 0.15, 1.0)), 1.0))
        smoothed = None
    width = cfg.alpha * rec.depth_scale_m
    if rec.labels and rng.random() < 0.9:
        lab = rec.labels[int(rng.integers(len(rec.labels)))]
        centre = rec.x_of_trace(lab["apex_trace"]) + rng.uniform(-0.3, 0.3) * width
    else:
        centre = rng.uniform(rec.x_m[0], rec.x_m[-1])
    image, left, w = depth_window(rec, centre, cfg, smoothed=smoothed)
    boxes, q = window_targets_m(rec, left, w, cfg.size)
    if rng.random() < 0.5:
        image = image[:, :, ::-1].copy()
        boxes = np.stack([cfg.size - boxes[:, 2], boxes[:, 1], cfg.size - boxes[:, 0], boxes[:, 3]], 1).reshape(-1, 4)
    return image, boxes.astype(np.float32), q, rec.direct_frac, rec.eps_r


def _loss(eps, q, batch_eps, batch_q, cfg: DepthTrainConfig):
    torch = require("torch")
    # eps_r in relative terms (its range is 3-20): MSE of the log; depth in fractions of the window depth
    le = torch.mean((torch.log(eps) - torch.log(batch_eps)) ** 2)
    ld = torch.mean((q - batch_q) ** 2) * 100.0 if q.numel() else eps.sum() * 0
    return cfg.lambda_eps * le + cfg.lambda_depth * ld, float(le.detach()), float(ld.detach())


def train_depthnet(cfg: DepthTrainConfig, records: list[DepthRecord], *, log=print, progress: bool = True,
                   max_seconds: float | None = None, validation: list[DepthRecord] | None = None) -> dict:
    """Train DepthNet on windows of ``records`` (with truth); checkpointed and resumable in ``cfg.out``."""
    torch = require("torch")

    records = [r for r in records if math.isfinite(r.eps_r)]
    if not records:
        raise GPR3DError("no records with a known eps_r to train DepthNet on")
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    device = resolve_device(cfg.device)
    net_cfg = DepthConfig(**cfg.net)
    torch.manual_seed(cfg.seed)
    model = build_depthnet(net_cfg)
    if cfg.init:
        start, start_net, _ = load_depthnet(cfg.init)
        if start_net != net_cfg:
            raise GPR3DError(f"--init {cfg.init}: a DepthNet {start_net.arch} width {start_net.width}, not "
                             f"{net_cfg.arch} width {net_cfg.width}")
        model.load_state_dict(start.state_dict())
    model = model.to(device)
    lr = cfg.lr or {"adamw": 1e-3, "reference": 4e-5}[cfg.optimiser]
    if cfg.optimiser == "adamw":
        opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    else:
        opt = torch.optim.SGD(model.parameters(), lr=lr, momentum=0.9, weight_decay=5e-5)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, warmup_cosine(min(100, max(cfg.steps // 10, 1)), cfg.steps))
    key = {k: v for k, v in asdict(cfg).items() if k not in ("out", "device", "checkpoint_every")}
    run = TrainingRun(out, model, opt, sched, steps=cfg.steps, resume_key=key,
                      config={"config": asdict(cfg), "n_records": len(records)},
                      columns="step,lr,loss,log_eps_mse,depth_mse_x100,wall_s", checkpoint_every=cfg.checkpoint_every,
                      device=device, desc="train depthnet", what="DepthNet training", log=log, progress=progress,
                      max_seconds=max_seconds)
    smoothed = {}

    def batch(step):  # step k's windows, drawn from its own seed: a resumed run draws what an unbroken one would
        rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, step, 0xD3]))
        items = []
        for _ in range(cfg.batch):
            k = int(rng.integers(len(records)))
            rec = records[k]
            if k not in smoothed:
                smoothed[k] = _smoothed(rec, net_cfg.alpha * rec.depth_scale_m, net_cfg.size)
            items.append(_training_item(rec, net_cfg, rng, smoothed[k]))
        return items

    def step_fn(items):
        images = torch.from_numpy(np.stack([it[0] for it in items])).to(device)
        rois = torch.from_numpy(_rois([it[1] for it in items])).to(device)
        tq = torch.from_numpy(np.concatenate([it[2] for it in items]).astype(np.float32)).to(device)
        direct = torch.tensor([it[3] for it in items], dtype=torch.float32, device=device)
        teps = torch.tensor([it[4] for it in items], dtype=torch.float32, device=device)
        eps, q = model(images, rois, direct)
        loss, le, ld = _loss(eps, q[:-1], teps, tq, cfg)
        return (loss, {"log_eps_mse": f"{le:.5f}", "depth_mse_x100": f"{ld:.5f}"},
                {"eps": f"{le:.3f}", "depth": f"{ld:.3f}"})

    run.run((batch(k) for k in range(run.step, cfg.steps)), step_fn)
    model.eval()
    return {"steps": run.step, "wall_s": run.wall_s, "model": model, "net": net_cfg,
            "parameters": int(sum(p.numel() for p in model.parameters()))}


def save_depthnet(model, net: DepthConfig, path, *, provenance: dict | None = None) -> None:
    """Write DepthNet's weights (float16) with its configuration and provenance, atomically."""
    torch = require("torch")
    obj = {"format": FORMAT, "version": 1, "net": asdict(net), "state_dict": half_state_dict(model),
           "provenance": provenance or {}}
    with atomic_path(path, suffix=".pt.part") as tmp:
        torch.save(obj, tmp)


def load_depthnet(path, *, device: str = "cpu"):
    """``(model in eval mode, DepthConfig, provenance)`` from a DepthNet weights file (``.pt``)."""
    p = Path(path)
    obj = read_weights_file(p, FORMAT, "DepthNet")
    net = DepthConfig(**obj["net"])
    model = build_depthnet(net)
    try:
        model.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in obj["state_dict"].items()})
    except RuntimeError:
        raise FormatError(p, f"weights do not fit DepthNet {net.arch} width {net.width}") from None
    return model.eval().to(resolve_device(device)), net, obj.get("provenance", {})


# ---------------------------------------------------------------------------------------------------- inference

class DepthEstimator:
    """DepthNet applied to a record and its detections.

    :meth:`estimate` gives the host's eps_r (the median over one window per
    detection, or over windows tiled along the record when there is none) with its
    uncertainty (the validation error the weights were shipped with, and the spread
    of the windows), and each box's depth to top.
    """

    def __init__(self, model, net: DepthConfig, provenance: dict | None = None, device: str = "cpu", session=None):
        self.model, self.net, self.provenance, self.device, self.session = model, net, provenance or {}, device, session

    @classmethod
    def load(cls, path=None, *, device: str = "cpu") -> "DepthEstimator":
        """From a ``.pt`` weights file (PyTorch, on ``device``) or its ``.onnx`` export (ONNX Runtime, on the CPU
        whatever ``device`` says: the network is small; the shipped default)."""
        p = Path(path) if path is not None else DEFAULT_DEPTHNET
        if p.suffix.lower() == ".onnx":
            session, net, prov = _onnx_session(p)
            return cls(None, net, prov, "cpu", session)
        model, net, prov = load_depthnet(p, device=device)
        return cls(model, net, prov, device)

    def _run(self, images: np.ndarray, rois: np.ndarray, direct: np.ndarray):
        if self.session is not None:
            eps, q = self.session.run(None, {"images": images, "rois": rois, "direct": direct})
            return eps, q
        torch = require("torch")
        with torch.no_grad():
            eps, q = self.model(torch.from_numpy(images).to(self.device), torch.from_numpy(rois).to(self.device),
                                torch.from_numpy(direct).to(self.device))
        return eps.cpu().numpy(), q.cpu().numpy()

    def predict(self, rec: DepthRecord, centres_m, boxes_per_window) -> tuple[np.ndarray, list[np.ndarray]]:
        """Raw outputs: eps per window and depth (m) per box, windows centred at ``centres_m``."""
        sm = _smoothed(rec, self.net.alpha * rec.depth_scale_m, self.net.size)
        images, boxes = [], []
        for c, bb in zip(centres_m, boxes_per_window):
            im, left, w = depth_window(rec, float(c), self.net, smoothed=sm)
            images.append(im)
            boxes.append(np.asarray([box_to_window(rec, b, left, w, self.net.size) for b in bb], np.float32).reshape(-1, 4))
        eps_all, q_all = [], []
        for k in range(0, len(images), 16):
            bx = boxes[k : k + 16]
            eps, q = self._run(np.stack(images[k : k + 16]).astype(np.float32), _rois(bx),
                               np.full(len(bx), rec.direct_frac, np.float32))
            eps_all.append(eps)
            q_all += [x * rec.depth_scale_m for x in _split(q, bx)]
        return np.concatenate(eps_all), q_all

    def estimate(self, survey, boxes, *, trace_spacing_m: float | None = None, record: DepthRecord | None = None):
        """``{"eps_r", "sigma_eps_r", "n_windows", "depth_m": [per box], "eps_r_windows": [...]}``."""
        rec = record or prepare_depth_record(survey, size=self.net.size, trace_spacing_m=trace_spacing_m)
        boxes = [list(map(float, b)) for b in boxes]
        if boxes:
            centres = [rec.x_of_trace(0.5 * (b[0] + b[2])) for b in boxes]
            per = [[b] for b in boxes]
        else:
            width = self.net.alpha * rec.depth_scale_m
            n = max(1, int(math.ceil((rec.x_m[-1] - rec.x_m[0]) / (0.5 * width))))
            centres = list(np.linspace(rec.x_m[0], rec.x_m[-1], n + 1)[: max(n, 1)] + 0.25 * width)
            per = [[] for _ in centres]
        eps_w, depths = self.predict(rec, centres, per)
        eps = float(np.median(eps_w))
        rel = float(self.provenance.get("validation", {}).get("eps_rel_rmse", 0.15))
        spread = 1.4826 * float(np.median(np.abs(eps_w - eps))) / math.sqrt(len(eps_w)) if len(eps_w) > 1 else 0.0
        return {"eps_r": eps, "sigma_eps_r": float(math.hypot(rel * eps, spread)), "n_windows": int(len(eps_w)),
                "eps_r_windows": [float(e) for e in eps_w],
                "depth_m": [float(d[0]) if d.size else float("nan") for d in depths] if boxes else []}


ONNX_OPSET = 17
_META = "gpr3d.depthnet"


def export_depthnet_onnx(weights, out) -> dict:
    """Export DepthNet weights (``.pt``) to ONNX at ``out`` (atomically; float16 weights as the detector's).

    Needs ``torch``, ``torchvision`` and ``onnx``; returns ``{"file", "bytes", "max_diff"}``: the largest
    difference of the graph's outputs from PyTorch's on test windows (eps_r relative, depth fractions of
    the window's depth).
    """
    torch = require("torch")
    require("onnx")  # a one-line hint when missing
    require("onnxruntime")
    import hashlib

    from gpr3d.io.onnxweights import finish_export

    model, net, prov = load_depthnet(weights)
    rng = np.random.default_rng(0)
    images = rng.random((2, 3, net.size, net.size), dtype=np.float32)
    rois = _rois([[[20, 30, 90, 80]], [[100, 50, 200, 120], [10, 10, 60, 40]]])
    direct = np.array([0.1, 0.2], np.float32)
    meta = {"net": asdict(net), "provenance": prov, "source_weights": Path(weights).name,
            "source_sha256": hashlib.sha256(Path(weights).read_bytes()).hexdigest(), "opset": ONNX_OPSET}
    with atomic_path(out, suffix=".onnx.part") as tmp:
        torch.onnx.export(model, (torch.from_numpy(images), torch.from_numpy(rois), torch.from_numpy(direct)),
                          str(tmp), opset_version=ONNX_OPSET, input_names=["images", "rois", "direct"],
                          output_names=["eps", "depth"], dynamo=False,
                          dynamic_axes={"images": {0: "B"}, "rois": {0: "K"}, "direct": {0: "B"},
                                        "eps": {0: "B"}, "depth": {0: "K"}})
        finish_export(tmp, _META, meta)
        sess, _, _ = _onnx_session(Path(tmp))
        got = sess.run(None, {"images": images, "rois": rois, "direct": direct})
        with torch.no_grad():
            ref = [x.numpy() for x in model(torch.from_numpy(images), torch.from_numpy(rois), torch.from_numpy(direct))]
        # eps relative; depth fractions against the window's depth (their scale is 0..0.6)
        diff = max(float(np.max(np.abs(got[0] - ref[0]) / ref[0])), float(np.max(np.abs(got[1] - ref[1]))))
    return {"file": str(out), "bytes": Path(out).stat().st_size, "max_diff": diff}


def _onnx_session(path: Path):
    from gpr3d.io.onnxweights import open_session

    sess, meta = open_session(path, _META, "DepthNet")
    return sess, DepthConfig(**meta["net"]), meta.get("provenance", {})


def validate_depthnet(model, net: DepthConfig, source, n: int) -> dict:
    """DepthNet alone on ``n`` labelled records ``source(i)`` (labelled boxes): the errors its weights ship with.

    ``{"n_records", "eps_rel_rmse", "eps_mape", "depth_mae_m"}``; ``eps_rel_rmse`` sets the
    uncertainty :class:`DepthEstimator` reports.
    """
    est = DepthEstimator(model.eval(), net)
    rel, derr = [], []
    for i in range(n):
        survey, lab = source(i)
        vis = [x for x in lab["labels"] if x.get("visible", True)]
        r = est.estimate(survey, [x["box"] for x in vis])
        rel.append(r["eps_r"] / lab["eps_r"] - 1)
        derr += [abs(d - x["depth_m"]) for d, x in zip(r["depth_m"], vis)]
    rel = np.asarray(rel)
    return {"n_records": int(n), "eps_rel_rmse": float(np.sqrt(np.mean(rel**2))),
            "eps_mape": float(np.mean(np.abs(rel))), "depth_mae_m": float(np.mean(derr)) if derr else float("nan")}
