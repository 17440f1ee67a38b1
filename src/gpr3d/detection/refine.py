"""Boxes placed by a dataset's label rule: a small network that moves each detected box.

A detector's box regression sees a hyperbola through 7 x 7 pooled features of a
network trained mostly on other data; the people who label a data set follow their
own rule for where a hyperbola's box ends (how far down its legs, how wide). The
refiner looks again at each box in the record's image: it crops a region twice the
box's size around it (``EXPAND``), resampled to ``CROP`` x ``CROP`` pixels
(sampled as torchvision's ``roi_align`` samples), and a four-stage convolutional network predicts how far
each edge must move, in box widths and heights (:func:`box_deltas`). It is trained on
the labels themselves, each shifted and resized at random as a detector's boxes are
wrong (:data:`JITTER`), mirrored at random (a hyperbola's box rule is symmetric), so
that training needs no detector run and takes minutes on two cores
(``references/detection/train_refiner.py``).

Images are the detector's own (:func:`record_image`: the whole record rendered as its
windows are), boxes are record boxes ``[trace0, t0_s, trace1, t1_s]``. The crops are cut
in NumPy (:func:`crop_array`, torchvision's ``roi_align`` sampling, separable along the
two axes); the network runs in PyTorch (:class:`BoxRefiner`) or, exported, in ONNX
Runtime (:class:`OnnxBoxRefiner`), so that ``gpr3d detect`` need not import PyTorch. The
mirrored look needs no second crop: cropping the mirrored picture about the mirrored box
gives the crop mirrored, so both looks go through the network in one batch.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from gpr3d.core.atomic import atomic_path
from gpr3d.core.deps import require
from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.io.coco import PixelMap
from gpr3d.io.weights import half_state_dict, read_weights_file

__all__ = ["CROP", "EXPAND", "JITTER", "FINE_JITTER_SCALE", "MIRROR", "PASSES", "MAX_PASSES", "DEFAULT_REFINER",
           "DEFAULT_REFINER_ONNX", "DEFAULT_FINE_REFINER", "DEFAULT_FINE_REFINER_ONNX",
           "record_image", "record_pixmap", "box_deltas", "apply_deltas", "mirror_deltas", "check_application",
           "jitter_boxes", "whole_boxes", "whole_apex", "pair_iou", "best_iou", "build_refiner", "RULES", "WIDE_JITTER",
           "QUALITY_WEIGHT", "check_rule", "check_quality_weight", "crop_array", "crops", "BoxRefiner", "OnnxBoxRefiner",
           "load_refiner", "save_refiner", "train_refiner", "export_refiner_onnx"]

CROP = 64  #: crop side in pixels
EXPAND = 2.0  #: the crop covers the box's width and height times this, about its centre
#: how training boxes are drawn about a label: centre shift (box widths), width and height
#: factors (log-normal sigma), top and bottom shifts (box heights): a detector's spread on
#: real data (``benchmarks/results/pgpr_box_fit.md``)
JITTER = {"centre": 0.06, "width": 0.2, "top": 0.1, "bottom": 0.15}
#: a fine stage's training boxes are drawn this much closer to their labels than :data:`JITTER`: the spread left
#: after the first refiner's moves
FINE_JITTER_SCALE = 0.5
#: the boxes a quality head also learns from (``train_refiner(quality=...)``): drawn this much wider about each
#: label, and as many again anywhere in the picture, so that it sees boxes half on a hyperbola and none on one
WIDE_JITTER = {"centre": 0.4, "width": 0.5, "top": 0.4, "bottom": 0.5}
#: the label rules a refiner's heads may follow: gpr3d's (``docs/labels.md``: recordings, simulated data) and the
#: P-GPR labellers' (their pictures: boxes ending higher up the legs)
RULES = ("gpr3d", "pgpr")
#: a detection's score times ``quality ** weight`` where the refiner has a quality head: None, the weight its
#: provenance gives the head's rule (``"quality_weights"``, measured when it was shipped; 1 where it gives none)
QUALITY_WEIGHT = None
#: applied with each crop also mirrored, the two edge moves averaged
MIRROR = True
#: applied this many times, each pass from the box the one before moved
PASSES = 2
MAX_PASSES = 5
FORMAT = "gpr3d.refiner"
DEFAULT_REFINER = Path(__file__).with_name("default_refiner.pt")
DEFAULT_REFINER_ONNX = Path(__file__).with_name("default_refiner.onnx")
DEFAULT_FINE_REFINER = Path(__file__).with_name("default_refiner_fine.pt")
DEFAULT_FINE_REFINER_ONNX = Path(__file__).with_name("default_refiner_fine.onnx")
_META = "gpr3d.refiner"
_MIN_SIDE = 2.0  # pixels: a box is never taken as thinner than this


def record_pixmap(survey, rows: int) -> PixelMap:
    """Pixels of the record image (:func:`record_image`): column ``c`` trace ``c``, row ``r`` time ``r`` rows."""
    spr = (survey.n_samples - 1) * survey.dt_s / (rows - 1)
    return PixelMap(trace0=-0.5, traces_per_px=1.0, t0_s=-0.5 * spr, s_per_px=spr)


def record_image(processed: np.ndarray, style: str = "channels") -> np.ndarray:
    """The whole record as the detector's windows show it: ``(3, rows, n_traces)`` float32.

    ``processed``: the detector's view ``(n_traces, rows)`` (:func:`gpr3d.detection.windows.prepare`).
    """
    from gpr3d.processing.image import record_scale, render_channels

    return render_channels(processed, style, scale=record_scale(processed))


def box_deltas(boxes, targets) -> np.ndarray:
    """How far each edge of ``boxes`` (k, 4) must move to reach ``targets``, in the box's width and height."""
    b, t = np.asarray(boxes, float).reshape(-1, 4), np.asarray(targets, float).reshape(-1, 4)
    wh = np.maximum(b[:, 2:] - b[:, :2], _MIN_SIDE)
    return np.concatenate([(t[:, :2] - b[:, :2]) / wh, (t[:, 2:] - b[:, 2:]) / wh], axis=1)


def apply_deltas(boxes, deltas) -> np.ndarray:
    """``boxes`` (k, 4) moved by ``deltas`` (:func:`box_deltas`'s inverse); an edge never crosses its partner."""
    b, d = np.asarray(boxes, float).reshape(-1, 4), np.asarray(deltas, float).reshape(-1, 4)
    wh = np.maximum(b[:, 2:] - b[:, :2], _MIN_SIDE)
    lo, hi = b[:, :2] + d[:, :2] * wh, b[:, 2:] + d[:, 2:] * wh
    mid = 0.5 * (lo + hi)
    return np.concatenate([np.minimum(lo, mid - 0.5), np.maximum(hi, mid + 0.5)], axis=1)


def whole_boxes(boxes, apex_traces, n_traces: int) -> np.ndarray:
    """Label boxes (k, 4; traces first) made whole where the record's first or last trace cuts them: a box that
    reaches one end of the record (within half a trace) but not the other is mirrored about its apex trace, so it
    reaches as far past that end as its uncut side reaches from the apex (hyperbolas are symmetric about their
    apex). Boxes cut on both sides or on none stay as they are."""
    b = np.array(boxes, float).reshape(-1, 4)
    a = np.asarray(apex_traces, float).reshape(-1)
    left, right = b[:, 0] <= 0.5, b[:, 2] >= n_traces - 1.5
    only_left, only_right = left & ~right, right & ~left
    b[only_left, 0] = np.minimum(b[only_left, 0], 2 * a[only_left] - b[only_left, 2])
    b[only_right, 2] = np.maximum(b[only_right, 2], 2 * a[only_right] - b[only_right, 0])
    return b


def whole_apex(box, n_traces: int, reach: float = 1.0) -> float | None:
    """The apex trace of a box refined by a refiner of whole hyperbolas (:func:`whole_boxes`): where the box reaches
    more than ``reach`` traces past exactly one end of the record, its centre (kept inside the record); else None
    (a box inside the record, or past both ends: the label rule's apex applies)."""
    i0, i1 = float(box[0]), float(box[2])
    past_first, past_last = i0 < -reach, i1 > n_traces - 1 + reach
    if past_first == past_last:
        return None
    return float(np.clip(0.5 * (i0 + i1), 0, n_traces - 1))


def mirror_deltas(deltas) -> np.ndarray:
    """Edge moves predicted for a mirrored crop, as moves of the unmirrored box: its left edge is the mirror's right
    one, moved the other way (and likewise the right edge); top and bottom stay."""
    d = np.asarray(deltas, float).reshape(-1, 4)
    return np.stack([-d[:, 2], d[:, 1], -d[:, 0], d[:, 3]], axis=1)


def check_application(mirror, passes) -> tuple[bool, int]:
    """``(mirror, passes)`` as a refiner applies them, or one line naming the wrong one."""
    if not isinstance(mirror, (bool, np.bool_)):
        raise InvalidDataError(f"the refiner's mirror setting must be True or False, got {mirror!r}")
    if isinstance(passes, (bool, np.bool_)) or not isinstance(passes, (int, np.integer)) \
            or not 1 <= passes <= MAX_PASSES:
        raise InvalidDataError(f"the refiner's passes must be a whole number in 1..{MAX_PASSES}, got {passes!r}")
    return bool(mirror), int(passes)


def jitter_boxes(boxes, n: int, rng, spread: dict | None = None) -> np.ndarray:
    """``n`` boxes drawn about each of ``boxes`` (k, 4) as a detector misses them (``JITTER``), label by label."""
    s = dict(JITTER, **(spread or {}))
    g = np.repeat(np.asarray(boxes, float).reshape(-1, 4), n, axis=0)
    w, h = g[:, 2] - g[:, 0], g[:, 3] - g[:, 1]
    cx = 0.5 * (g[:, 0] + g[:, 2]) + rng.normal(0, s["centre"], len(g)) * w
    half = 0.5 * w * np.exp(rng.normal(0, s["width"], len(g)))
    top = g[:, 1] + rng.normal(0, s["top"], len(g)) * h
    bottom = np.maximum(g[:, 3] + rng.normal(0, s["bottom"], len(g)) * h, top + 0.1 * h + 1)
    return np.stack([cx - half, top, cx + half, bottom], axis=1)


def build_refiner(heads: int = 1, quality: bool = False, members: int = 1, seed: int = 0):
    """A fresh refiner network: ``(n, 3, CROP, CROP)`` crops in, ``(n, heads * (4 + quality))`` out: for each label
    rule's head (:data:`RULES`) its four edge moves and, with ``quality``, the logit of the box's IoU with the label
    it stands for; its weights drawn from ``seed``. With ``members`` > 1, that many such networks (``.members``,
    member ``k`` drawn from ``seed + k``) whose outputs are averaged: one file and one graph for an ensemble trained
    member by member."""
    torch = require("torch")
    nn = torch.nn
    if isinstance(members, bool) or not isinstance(members, int) or members < 1:
        raise InvalidDataError(f"a refiner's members must be a whole number >= 1, got {members!r}")

    def stage(i, o):
        return nn.Sequential(nn.Conv2d(i, o, 3, 2, 1), nn.BatchNorm2d(o), nn.ReLU(inplace=True))

    def one(seed):
        torch.manual_seed(seed)
        side = CROP // 16
        return nn.Sequential(stage(3, 32), stage(32, 48), stage(48, 64), stage(64, 96), nn.Flatten(),
                             nn.Linear(96 * side * side, 256), nn.ReLU(inplace=True),
                             nn.Linear(256, heads * (4 + int(bool(quality)))))

    if members == 1:
        return one(seed)

    class Average(nn.Module):
        def __init__(self, nets):
            super().__init__()
            self.members = nn.ModuleList(nets)

        def forward(self, x):
            return torch.stack([m(x) for m in self.members]).mean(dim=0)

    return Average([one(seed + k) for k in range(members)])


def _members(provenance: dict, where) -> int:
    """How many networks a refiner file averages (its provenance's ``"members"``, 1 where it names none); one line
    where that is not a whole number >= 1."""
    m = provenance.get("members", 1)
    if isinstance(m, bool) or not isinstance(m, int) or m < 1:
        raise FormatError(where, f"a refiner of {m!r} members; a whole number >= 1 was expected")
    return m


def _regions(boxes: np.ndarray):
    """Crop regions ``(k, 4)`` float32: each box's centre, ``EXPAND`` times its sides (at least ``_MIN_SIDE``)."""
    f = np.float32
    c = f(0.5) * (boxes[:, :2] + boxes[:, 2:])
    wh = np.maximum(boxes[:, 2:] - boxes[:, :2], f(_MIN_SIDE))
    return np.concatenate([c - f(0.5 * EXPAND) * wh, c + f(0.5 * EXPAND) * wh], axis=1)


def _taps(lo: np.ndarray, hi: np.ndarray, size: int):
    """Along one axis of ``size`` pixels, for regions ``lo..hi`` (k,): the ``CROP`` bins' four taps each, pixel
    indices ``(k, CROP, 4)`` and weights (their sum is 1 inside the picture). A bin is the mean of two samples at a
    quarter and three quarters of it; a sample at ``x`` (pixel ``i`` holds ``i + 0.5``) weighs its two neighbouring
    pixels linearly; samples more than a pixel outside count zero, those within it take the edge pixel: torchvision's
    ``roi_align`` (``aligned=True``, ``sampling_ratio=2``), computed in float32 as it computes."""
    f = np.float32
    step = (hi - lo) / f(CROP)
    bins, within = np.arange(CROP, dtype=f).repeat(2), np.tile(np.array([0.5, 1.5], f), CROP)
    # in torchvision's order of operations, so that float32 rounds alike
    x = (lo - f(0.5))[:, None] + bins[None] * step[:, None] + within[None] * step[:, None] / f(2)
    inside = (x >= f(-1.0)) & (x <= f(size))
    x = np.maximum(x, f(0.0))
    low = x.astype(np.int64)
    edge = low >= size - 1
    low = np.where(edge, size - 1, low)
    frac = np.where(edge, f(0.0), x - low.astype(f))
    high = np.where(edge, low, low + 1)
    w_low, w_high = (f(0.5) - f(0.5) * frac) * inside, f(0.5) * frac * inside
    k = len(lo)
    index = np.stack([low, high], axis=-1).reshape(k, CROP, 4)
    weight = np.stack([w_low, w_high], axis=-1).reshape(k, CROP, 4)
    return index, weight


def crop_array(image, boxes_px) -> np.ndarray:
    """``(k, 3, CROP, CROP)`` float32 crops of ``image`` (3, rows, cols) around ``boxes_px`` (k, 4) in its pixels:
    each box's region ``EXPAND`` times its sides about its centre, each bin the mean of 2 x 2 bilinear samples as
    torchvision's ``roi_align`` takes them (``aligned=True``, ``sampling_ratio=2``), computed separably: rows first,
    then columns, two small gathers a box."""
    img = np.asarray(image, np.float32)
    b = np.asarray(boxes_px, np.float32).reshape(-1, 4)
    out = np.empty((len(b), img.shape[0], CROP, CROP), np.float32)
    if not len(b):
        return out
    reg = _regions(b)
    xi, xw = _taps(reg[:, 0], reg[:, 2], img.shape[2])
    yi, yw = _taps(reg[:, 1], reg[:, 3], img.shape[1])
    for i in range(len(b)):
        c0 = int(xi[i].min())
        rows = np.einsum("crtx,rt->crx", img[:, yi[i], c0 : int(xi[i].max()) + 1], yw[i])  # (3, CROP, columns)
        out[i] = np.einsum("crqt,qt->crq", rows[:, :, xi[i] - c0], xw[i])
    return out


def crops(image, boxes_px):
    """:func:`crop_array` as a torch tensor (what training feeds the network)."""
    torch = require("torch")
    if torch.is_tensor(image):
        image = image.detach().cpu().numpy()
    return torch.from_numpy(crop_array(image, boxes_px))


def _refined(survey, rows, boxes, image, predict_crops, *, mirror: bool, passes: int, head: int = 0,
             quality: bool = False, score: bool = False, fine=None):
    """Record boxes moved with ``predict_crops(crops (n, 3, CROP, CROP))`` (per head: edge moves, and with
    ``quality`` the IoU logit; ``head`` picks the columns), ``passes`` times; with ``mirror`` each pass averages
    the moves for the box and for its mirror image in the mirrored picture: the crops mirrored (the same bins, in
    the other order), both looks in one batch. ``fine``: ``(predict_crops, head)`` of a fine stage (edge moves
    alone), applied once more after the passes, as they are. Returns ``(boxes, quality)``: with ``score`` (and a
    ``quality`` head) each final box's predicted IoU with its label (a last look at the boxes where they ended,
    both looks' mean), else None."""
    b = np.asarray(boxes, float).reshape(-1, 4)
    width = 4 + int(quality)
    if not len(b):
        return b, (np.zeros(0) if quality and score else None)
    pm = record_pixmap(survey, rows)
    px = np.array([pm.box_to_px(x) for x in b])
    img = np.asarray(image, np.float32)

    def look(px, predict=predict_crops, hd=head, w=width):
        c = crop_array(img, px)
        out = np.asarray(predict(np.concatenate([c, c[..., ::-1]]) if mirror else c), float)
        return out[:, hd * w : (hd + 1) * w]

    def move(px, o):
        d = 0.5 * (o[: len(px), :4] + mirror_deltas(o[len(px) :, :4])) if mirror else o[:, :4]
        return apply_deltas(px, d)

    for _ in range(passes):
        px = move(px, look(px))
    if fine is not None:
        px = move(px, look(px, fine[0], fine[1], 4))
    q = None
    if quality and score:
        q = 1.0 / (1.0 + np.exp(-look(px)[:, 4]))
        q = 0.5 * (q[: len(px)] + q[len(px) :]) if mirror else q
    return np.array([pm.px_to_box(x) for x in px]), q


def pair_iou(a, b) -> np.ndarray:
    """IoU of each box of ``a`` (..., 4) with the box of ``b`` in the same place (broadcast)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ix = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    iy = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = ix * iy
    union = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1]) + (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1]) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _heads(provenance: dict, where) -> tuple[tuple, bool]:
    """``(rules, quality)`` of a refiner from its provenance: the label rules of its heads (``()``: one head, the
    rule of whatever it was trained on) and whether each head has a quality output; one line where they are not
    what this gpr3d knows."""
    rules, quality = provenance.get("rules") or (), provenance.get("quality", False)
    if not isinstance(rules, (list, tuple)) or not all(r in RULES for r in rules) or len(set(rules)) != len(rules):
        raise FormatError(where, f"a refiner whose heads follow the label rules {rules!r}; this gpr3d knows "
                                 f"{', '.join(RULES)}")
    if not isinstance(quality, bool):
        raise FormatError(where, f"a refiner whose quality setting is {quality!r}, not true or false")
    weights = provenance.get("quality_weights", {})
    try:
        ok = isinstance(weights, dict) and all(k in RULES and check_quality_weight(v) is not None
                                               for k, v in weights.items())
    except InvalidDataError:
        ok = False
    if not ok:
        raise FormatError(where, f"a refiner whose quality weights are {weights!r}: a rule's weight is a number "
                                 "in 0..8")
    return tuple(rules), quality


def check_rule(rule) -> str:
    """A box rule as a refiner takes it: ``"auto"`` or one of :data:`RULES`; else one line naming it."""
    if rule != "auto" and rule not in RULES:
        raise InvalidDataError(f"box rule must be auto or one of {', '.join(RULES)}, got {rule!r}")
    return rule


def check_quality_weight(weight) -> float | None:
    """The exponent of a refiner's quality on the scores (:data:`QUALITY_WEIGHT`): None (the refiner's own for each
    rule) or a number in 0..8."""
    if weight is None:
        return None
    if isinstance(weight, (bool, np.bool_)) or not isinstance(weight, (int, float, np.integer, np.floating)) \
            or not 0.0 <= float(weight) <= 8.0:
        raise InvalidDataError(f"the quality weight must be a number in 0..8, got {weight!r}")
    return float(weight)


class BoxRefiner:
    """A trained refiner (PyTorch); :meth:`refine` moves record boxes onto its label rule.

    ``mirror`` and ``passes`` say how it is applied (:data:`MIRROR`, :data:`PASSES`); ``rule`` which head
    a refiner of several label rules uses (``"auto"``: P-GPR's for pictures, gpr3d's for recordings);
    ``quality_weight`` how much a quality head's predicted IoU rescales the scores (:meth:`weight_for`).
    """

    mirror = MIRROR
    passes = PASSES
    rule = "auto"
    quality_weight = QUALITY_WEIGHT
    #: a fine stage (a refiner trained on boxes drawn closer to the labels, :data:`FINE_JITTER_SCALE`) that moves
    #: each box once more after the passes, with the head of the same rule; None: none (:meth:`with_fine`)
    fine = None

    def __init__(self, net, provenance: dict | None = None):
        self.net, self.provenance = net.eval(), provenance or {}
        self.rules, self.quality = _heads(self.provenance, "refiner")

    @property
    def whole(self) -> bool:
        """Trained on whole hyperbolas' boxes (``train_refiner.py --whole``): a box it moves past the record's end
        has its apex at its centre (:func:`whole_apex`)."""
        return bool(self.provenance.get("whole", False))

    @classmethod
    def load(cls, path=None) -> "BoxRefiner":
        p = Path(path) if path is not None else DEFAULT_REFINER
        obj = read_weights_file(p, FORMAT, "box refiner")
        if obj.get("crop") != CROP or obj.get("expand") != EXPAND:
            raise FormatError(p, f"a refiner for {obj.get('crop')} px crops x {obj.get('expand')}, this gpr3d makes "
                                 f"{CROP} px x {EXPAND}")
        rules, quality = _heads(obj.get("provenance") or {}, p)
        net = build_refiner(max(len(rules), 1), quality, _members(obj.get("provenance") or {}, p))
        try:
            net.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in obj["state_dict"].items()})
        except RuntimeError as exc:
            raise FormatError(p, f"weights do not fit the refiner: {str(exc).splitlines()[-1].strip()[:160]}") from None
        return cls(net, obj.get("provenance"))

    def head_for(self, survey) -> tuple[int, str | None]:
        """``(head, rule)`` this refiner applies to ``survey``'s boxes: with one head ``(0, None)``; else the head
        of :attr:`rule`, or with ``"auto"`` P-GPR's for a picture (``metadata["format"] == "picture"``) and
        gpr3d's for a recording."""
        rule = check_rule(self.rule)
        if not self.rules:
            if rule != "auto":
                raise InvalidDataError(f"box rule {rule}: this refiner has one head (no rules to choose from)")
            return 0, None
        if rule == "auto":
            picture = (getattr(survey, "metadata", None) or {}).get("format") == "picture"
            rule = "pgpr" if picture and "pgpr" in self.rules else ("gpr3d" if "gpr3d" in self.rules else self.rules[0])
        if rule not in self.rules:
            raise InvalidDataError(f"box rule {rule}: this refiner's heads follow {', '.join(self.rules)}")
        return self.rules.index(rule), rule

    def weight_for(self, survey) -> float | None:
        """The weight of the quality on ``survey``'s scores (None: no quality head): :attr:`quality_weight` where
        given, else the weight the refiner's provenance gives the rule of its head (``"quality_weights"``; 1 where
        it gives none)."""
        if not self.quality:
            return None
        if self.quality_weight is not None:
            return float(self.quality_weight)
        rule = self.head_for(survey)[1]
        return float(self.provenance.get("quality_weights", {}).get(rule, 1.0))

    def predict_crops(self, crops_) -> np.ndarray:
        """The network's outputs ``(n, heads x (4 + quality))`` for crops ``(n, 3, CROP, CROP)`` (:func:`crop_array`):
        each head's edge moves (and its quality logit)."""
        torch = require("torch")
        with torch.inference_mode():
            return self.net(torch.from_numpy(np.ascontiguousarray(crops_, np.float32))).numpy().astype(float)

    def predict(self, image, boxes_px) -> np.ndarray:
        """The outputs (:meth:`predict_crops`) for boxes in pixels of ``image`` (1, 3, rows, cols)."""
        return self.predict_crops(crop_array(np.asarray(image)[0], boxes_px))

    def refine(self, survey, rows: int, boxes, image):
        """``boxes`` (k, 4) of ``survey`` moved onto the label rule; ``image``: the record's :func:`record_image`
        of ``rows`` rows."""
        return self.refine_scored(survey, rows, boxes, image, score=False)[0]

    def quality_of(self, survey, rows: int, boxes, image) -> np.ndarray:
        """Each of ``boxes``' predicted IoU with the label it stands for, where they are (not moved first): the
        quality head of the rule :meth:`head_for` picks, both looks' mean with :attr:`mirror`. A refiner without a
        quality head: one line."""
        if not self.quality:
            raise InvalidDataError(f"{self.provenance.get('name', 'this refiner')} has no quality head")
        mirror, _ = check_application(self.mirror, self.passes)
        head, _ = self.head_for(survey)
        return _refined(survey, rows, boxes, image, self.predict_crops, mirror=mirror, passes=0, head=head,
                        quality=True, score=True)[1]

    def refine_scored(self, survey, rows: int, boxes, image, *, score: bool = True):
        """``(boxes moved onto the label rule, quality)``: with a quality head (and ``score``) each moved box's
        predicted IoU with the label it stands for, in 0..1, else None."""
        mirror, passes = check_application(self.mirror, self.passes)
        head, rule = self.head_for(survey)
        return _refined(survey, rows, boxes, image, self.predict_crops, mirror=mirror, passes=passes, head=head,
                        quality=self.quality, score=score, fine=self.fine_for(survey))

    def fine_for(self, survey):
        """``(predict_crops, head)`` of the fine stage for ``survey``'s boxes: its head of the rule this refiner
        applies (:meth:`head_for`), or its one head; None without a fine stage, or one with no head of that rule."""
        if self.fine is None:
            return None
        rule = self.head_for(survey)[1]
        if not self.fine.rules:
            return self.fine.predict_crops, 0
        return (self.fine.predict_crops, self.fine.rules.index(rule)) if rule in self.fine.rules else None

    def with_fine(self, fine: "BoxRefiner | None") -> "BoxRefiner":
        """This refiner with ``fine`` as its fine stage (None: none), after checking that ``fine`` has heads of this
        refiner's label rules (some of them: the others' boxes are not moved again; or one head where this refiner
        has one), the same kind of boxes (whole hyperbolas' or not, where it has gpr3d's rule or one head) and no
        quality head of its own (the quality is this refiner's); returns ``self``."""
        if fine is not None:
            name = fine.provenance.get("name", "the fine stage")
            if bool(fine.rules) != bool(self.rules) or not set(fine.rules) <= set(self.rules):
                raise InvalidDataError(f"{name}: a fine stage whose heads follow "
                                       f"{', '.join(fine.rules) or 'one rule'}, the refiner's "
                                       f"{', '.join(self.rules) or 'one rule'}")
            if fine.quality:
                raise InvalidDataError(f"{name}: a fine stage with a quality head (the first refiner's is used)")
            # (whole hyperbolas' boxes are taught where labels name apexes, gpr3d's rule; P-GPR's pictures have none)
            if fine.whole != self.whole and (not fine.rules or "gpr3d" in fine.rules):
                raise InvalidDataError(f"{name}: a fine stage {'not ' if not fine.whole else ''}trained on whole "
                                       f"hyperbolas' boxes, the refiner {'not ' if not self.whole else ''}so")
        self.fine = fine
        return self


class OnnxBoxRefiner(BoxRefiner):
    """The refiner exported with its cropping (:func:`export_refiner_onnx`), run by ONNX Runtime."""

    def __init__(self, session, provenance: dict | None = None):
        self.session, self.provenance = session, provenance or {}
        self.rules, self.quality = _heads(self.provenance, "refiner graph")

    @classmethod
    def load(cls, path=None) -> "OnnxBoxRefiner":
        from gpr3d.io.onnxweights import open_session

        p = Path(path) if path is not None else DEFAULT_REFINER_ONNX
        # a pool of ONNX Runtime's size whose threads sleep between runs: a spinning second pool beside the
        # detector's slowed it; one thread took 13.2 ms a call of a box-rich window's (28 boxes, when the graph
        # still cropped: RoiAlign 9.2 ms of it), two sleeping threads 7.4 ms (Intel rocketlake, 2 cores)
        sess, meta = open_session(p, _META, "refiner", spin=False)
        if meta.get("crop") != CROP or meta.get("expand") != EXPAND:
            raise FormatError(p, f"a refiner for {meta.get('crop')} px crops x {meta.get('expand')}, this gpr3d "
                                 f"makes {CROP} px x {EXPAND}")
        inputs = [i.name for i in sess.get_inputs()]
        if inputs != ["crops"]:
            raise FormatError(p, f"a refiner graph taking {', '.join(inputs)} (an export of an older gpr3d, which "
                                 "cropped inside the graph); export its weights again (export_refiner_onnx)")
        rules, quality = _heads(meta.get("provenance") or {}, p)
        width = sess.get_outputs()[0].shape[-1]
        if width != max(len(rules), 1) * (4 + quality):
            raise FormatError(p, f"a refiner graph of {width} outputs a box where its provenance says "
                                 f"{max(len(rules), 1)} head(s){' with quality' if quality else ''}")
        return cls(sess, meta.get("provenance"))

    def predict_crops(self, crops_) -> np.ndarray:
        return self.session.run(None, {"crops": np.ascontiguousarray(crops_, np.float32)})[0].astype(float)


def load_refiner(path=None, *, engine: str = "torch", mirror: bool = MIRROR, passes: int = PASSES,
                 rule: str = "auto", quality_weight: float = QUALITY_WEIGHT, fine="auto") -> BoxRefiner:
    """The refiner in ``path`` (default: the shipped one): ``.pt`` in PyTorch, ``.onnx`` in ONNX Runtime.

    ``engine="onnx"`` with no path loads the shipped ONNX export. ``mirror``, ``passes``, ``rule``,
    ``quality_weight``: how it is applied (:class:`BoxRefiner`), checked before the file is read (a rule the
    refiner has no head for: one line once it is read). ``fine``: its fine stage (:attr:`BoxRefiner.fine`):
    ``"auto"`` the shipped one with the shipped refiner and none with another, ``"none"`` (or None) none, or a
    refiner's ``.pt``/``.onnx`` file.
    """
    mirror, passes = check_application(mirror, passes)
    rule, quality_weight = check_rule(rule), check_quality_weight(quality_weight)
    if fine == "auto":
        fine = "default" if path is None else None
    if fine not in (None, "none", "default") and not isinstance(fine, (str, Path)):
        raise InvalidDataError(f"the fine stage must be auto, none, default or a refiner's file, got {fine!r}")
    onnx = (path is not None and str(path).lower().endswith(".onnx")) or (path is None and engine == "onnx")
    ref = OnnxBoxRefiner.load(path) if onnx else BoxRefiner.load(path)
    ref.mirror, ref.passes, ref.rule, ref.quality_weight = mirror, passes, rule, quality_weight
    if rule != "auto" and rule not in ref.rules:
        raise InvalidDataError(f"box rule {rule}: this refiner's heads follow {', '.join(ref.rules)}" if ref.rules
                               else f"box rule {rule}: this refiner has one head (no rules to choose from)")
    if fine == "default":
        fine = DEFAULT_FINE_REFINER_ONNX if onnx else DEFAULT_FINE_REFINER
    if fine not in (None, "none"):
        stage = OnnxBoxRefiner.load(fine) if str(fine).lower().endswith(".onnx") else BoxRefiner.load(fine)
        ref.with_fine(stage)
    return ref


def save_refiner(net, path, *, provenance: dict | None = None) -> None:
    """Write a refiner's weights (float16) atomically with its crop settings and provenance."""
    torch = require("torch")
    obj = {"format": FORMAT, "version": 1, "crop": CROP, "expand": EXPAND, "state_dict": half_state_dict(net),
           "provenance": provenance or {}}
    with atomic_path(path, suffix=".pt.part") as tmp:
        torch.save(obj, tmp)


def export_refiner_onnx(weights=None, out=DEFAULT_REFINER_ONNX) -> dict:
    """Export a refiner weights file (default: the shipped one) to ONNX, atomically: crops
    ``(n, 3, CROP, CROP)`` in (input ``crops``, any ``n``), edge moves ``(n, 4)`` out.

    Returns ``{"file", "bytes", "max_abs_diff", "max_quality_diff"}``: the largest difference of the graph's
    edge moves from PyTorch's on the crops of a test image (noise: larger moves than real crops ask), and of its
    predicted qualities (IoU, 0..1; None without a quality head).
    """
    torch = require("torch")
    require("onnx")
    ort = require("onnxruntime")
    from gpr3d.io.onnxweights import finish_export

    src = Path(weights) if weights is not None else DEFAULT_REFINER
    ref = BoxRefiner.load(src)
    rng = np.random.default_rng(0)
    image = rng.random((3, 64, 300), dtype=np.float32)
    test = crop_array(image, np.array([[20, 10, 80, 30], [150, 5, 260, 50], [0, 0, 40, 63]], np.float32))
    meta = {"crop": CROP, "expand": EXPAND, "provenance": ref.provenance, "source_weights": src.name,
            "source_sha256": hashlib.sha256(src.read_bytes()).hexdigest()}
    with atomic_path(out, suffix=".onnx.part") as tmp:
        torch.onnx.export(ref.net.eval(), (torch.from_numpy(test),), str(tmp), opset_version=17,
                          input_names=["crops"], output_names=["deltas"], dynamo=False,
                          dynamic_axes={"crops": {0: "n"}, "deltas": {0: "n"}})
        finish_export(tmp, _META, meta)
        sess = ort.InferenceSession(str(tmp), providers=["CPUExecutionProvider"])
        got, want = sess.run(None, {"crops": test})[0], ref.predict_crops(test)
    width = 4 + int(ref.quality)
    moves = [c for c in range(got.shape[1]) if c % width < 4]
    diff = float(np.abs(got[:, moves] - want[:, moves]).max())
    qdiff = None
    if ref.quality:
        def sig(x):
            return 1.0 / (1.0 + np.exp(-np.asarray(x, float)))
        qdiff = float(np.abs(sig(got[:, 4::width]) - sig(want[:, 4::width])).max())
    return {"file": str(out), "bytes": Path(out).stat().st_size, "max_abs_diff": diff, "max_quality_diff": qdiff}


def _random_boxes(labels, n: int, cols: int, rows: int, rng) -> np.ndarray:
    """``n`` boxes the size of ``labels``' (one drawn at random, its sides times a log-normal factor) placed anywhere
    in a ``cols`` x ``rows`` picture."""
    g = np.asarray(labels, float).reshape(-1, 4)[rng.integers(0, len(labels), n)]
    w = np.minimum((g[:, 2] - g[:, 0]) * np.exp(rng.normal(0, 0.4, n)), cols - 1.0)
    h = np.minimum((g[:, 3] - g[:, 1]) * np.exp(rng.normal(0, 0.4, n)), rows - 1.0)
    x0, y0 = rng.uniform(0, cols - w), rng.uniform(0, rows - h)
    return np.stack([x0, y0, x0 + w, y0 + h], axis=1)


def best_iou(boxes, labels, cols: int | None = None) -> np.ndarray:
    """Each of ``boxes`` (k, 4)' IoU with the label (m, 4) it overlaps most (0 where there is none); with ``cols``
    the boxes are first cut to the picture's columns, as detections are cut to the record."""
    b = np.asarray(boxes, float).reshape(-1, 4).copy()
    g = np.asarray(labels, float).reshape(-1, 4)
    if cols is not None:
        b[:, [0, 2]] = np.clip(b[:, [0, 2]], 0.0, float(cols))
    if not len(g) or not len(b):
        return np.zeros(len(b))
    return pair_iou(b[:, None, :], g[None, :, :]).max(axis=1)


def train_refiner(samples, *, epochs: int = 9, per_label: int = 24, batch: int = 128, lr: float = 2e-3,
                  seed: int = 0, log=None, heads: int = 1, quality: int = 0, quality_loss: float = 0.2,
                  jitter_scale: float = 1.0):
    """A refiner trained on ``samples``: an iterable of ``(image (3, rows, cols), label boxes px (k, 4))``,
    ``(image, label boxes, whole boxes (k, 4) or None)`` or ``(image, label boxes, whole boxes or None, head)``
    (the label rule's head, ``0 <= head < heads``, that the sample teaches; 0 where not given). Where whole boxes are
    given the boxes drawn and aimed at are those (the label boxes, cut to the record, are what a quality head's
    IoU is measured against).

    Each label gives ``per_label`` boxes drawn about it (:func:`jitter_boxes`, its spread times
    ``jitter_scale``: a fine stage, :data:`FINE_JITTER_SCALE`, learns the smaller moves left after the
    first refiner's), each crop mirrored at random; the target is the label. Where a sample gives target boxes (a
    hyperbola cut by the record's first or last trace, whose whole box reaches past
    it: :func:`whole_boxes`), the boxes are drawn about the target and half of them are
    cut to the picture's columns, as a detector's boxes are: the refiner learns to
    reach past the record's end to the whole hyperbola. One-cycle AdamW, smooth L1 on
    the edge moves. With ``quality`` > 0 each head also learns the IoU of a box with the
    label it stands for (binary cross-entropy on the logit, weighted ``quality_loss``),
    from those boxes and ``quality`` more a label drawn wider (:data:`WIDE_JITTER`) and
    as many anywhere in the picture (:func:`best_iou`). Crops are held in float16.
    Returns the network in eval mode.
    """
    torch = require("torch")
    if epochs < 1 or per_label < 1 or batch < 1 or heads < 1 or quality < 0:
        raise InvalidDataError(f"epochs, per_label, batch and heads must be positive and quality not negative, got "
                               f"{epochs}, {per_label}, {batch}, {heads}, {quality}")
    if isinstance(jitter_scale, bool) or not isinstance(jitter_scale, (int, float)) or not 0.0 < jitter_scale <= 4.0:
        raise InvalidDataError(f"the jitter scale must be a number in (0, 4], got {jitter_scale!r}")
    spread = {k: v * jitter_scale for k, v in JITTER.items()}
    rng = np.random.default_rng(seed)
    xs, ys, masks, qs, hs = [], [], [], [], []
    for image, labels, *rest in samples:
        whole = rest[0] if rest and rest[0] is not None else None
        head = int(rest[1]) if len(rest) > 1 else 0
        if not 0 <= head < heads:
            raise InvalidDataError(f"a sample names head {head}, the refiner has {heads}")
        lab = np.asarray(labels, float).reshape(-1, 4)
        g = np.asarray(whole if whole is not None else labels, float).reshape(-1, 4)
        if not len(g):
            continue
        jb = jitter_boxes(g, per_label, rng, spread)
        rows, cols = np.asarray(image).shape[-2:]
        if whole is not None:  # half cut to the record's traces (pixel c + 0.5 is trace c), as the detector's are
            cut = rng.random(len(jb)) < 0.5
            jb[cut, 0] = np.clip(jb[cut, 0], 0.5, cols - 2.5)
            jb[cut, 2] = np.clip(jb[cut, 2], jb[cut, 0] + 2, cols - 0.5)
        y = box_deltas(jb, np.repeat(g, per_label, axis=0))
        mask = np.ones(len(jb), bool)
        if quality:
            more = np.concatenate([jitter_boxes(lab if len(lab) else g, quality, rng, WIDE_JITTER),
                                   _random_boxes(lab if len(lab) else g, quality * max(len(lab), 1), cols, rows, rng)])
            jb = np.concatenate([jb, more])
            y = np.concatenate([y, np.zeros((len(more), 4))])
            mask = np.concatenate([mask, np.zeros(len(more), bool)])
            qs.append(torch.as_tensor(best_iou(jb, lab, cols), dtype=torch.float32))
        xs.append(crops(image, jb).half())
        ys.append(torch.as_tensor(y, dtype=torch.float32))
        masks.append(torch.as_tensor(mask))
        hs.append(torch.full((len(jb),), head, dtype=torch.int64))
    if not xs:
        raise InvalidDataError("no labelled boxes to train the refiner on")
    x_all, y_all, m_all, h_all = torch.cat(xs), torch.cat(ys), torch.cat(masks), torch.cat(hs)
    del xs
    q_all = torch.cat(qs) if quality else None
    width = 4 + int(bool(quality))
    net = build_refiner(heads, bool(quality), seed=seed)
    torch.manual_seed(seed)
    opt = torch.optim.AdamW(net.parameters(), lr / 2, weight_decay=1e-4)
    n = len(x_all)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, lr, total_steps=epochs * ((n + batch - 1) // batch))
    for epoch in range(epochs):
        net.train()
        order, total = torch.randperm(n), 0.0
        for i in range(0, n, batch):
            idx = order[i : i + batch]
            x, y = x_all[idx].float(), y_all[idx].clone()
            flip = torch.rand(len(idx)) < 0.5  # mirrored: left and right edges swap, and change sign
            x[flip] = x[flip].flip(-1)
            y[flip, 0], y[flip, 2] = -y_all[idx][flip, 2], -y_all[idx][flip, 0]
            out = net(x).view(len(idx), heads, width)[torch.arange(len(idx)), h_all[idx]]
            m = m_all[idx]
            loss = torch.nn.functional.smooth_l1_loss(out[m, :4], y[m], beta=0.05) if bool(m.any()) else out.sum() * 0
            if quality:
                loss = loss + quality_loss * torch.nn.functional.binary_cross_entropy_with_logits(out[:, 4], q_all[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        if log:
            log(f"epoch {epoch + 1}/{epochs}: loss {total / n:.4f} over {n} crops")
    return net.eval()
