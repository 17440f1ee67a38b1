"""Running a detector on a whole record: windows in, boxes in traces and seconds out.

>>> from gpr3d.detection import Detector
>>> det = Detector.load()                      # the shipped default weights   # doctest: +SKIP
>>> result = det.detect(gpr3d.read("FILE____032.DZT"))                          # doctest: +SKIP
>>> result["targets"][0]     # {"box": [i0, t0_s, i1, t1_s], "score", "apex_trace", "apex_time_s"}  # doctest: +SKIP
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from gpr3d.core.deps import require
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.timing import stage
from gpr3d.detection.windows import (DUPLICATE_IOU, WindowConfig, apex_of_box, fuse_views, merge, prepare,
                                     rows_interval, soften_duplicates, trace_width, width_rate, windows)
from gpr3d.processing.analytic import running_mean
from gpr3d.processing.image import equalise_rows

__all__ = ["Detector", "load_detector", "fastest_engine", "ENGINES", "REAL_FORMATS"]

#: how a detector runs: "torch" (PyTorch, any device), "onnx" (ONNX Runtime on the CPU, no PyTorch
#: import: the faster start), "int8" (the shipped model's 8-bit graph in ONNX Runtime: about 0.7x the float
#: graph's time a window; live mode's default), "auto" (onnx for the shipped model on the CPU when ONNX
#: Runtime is installed, else torch)
ENGINES = ("auto", "torch", "onnx", "int8")


def load_detector(path=None, *, device: str = "cpu", engine: str = "auto", refiner="auto", refine_mirror=None,
                  refine_passes=None, box_rule: str = "auto", quality_weight=None, fine_refiner="auto") -> "Detector":
    """The detector in ``path`` (default: the shipped one), run by ``engine`` (see ``ENGINES``).

    ``path`` may be a ``.pt`` weights file (torch) or an ``.onnx`` export of one (onnx).
    ``refiner``: the box refiner that places its boxes (:mod:`gpr3d.detection.refine`):
    ``"auto"`` the shipped one with the shipped detector and none with other weights,
    ``"none"`` (or None) none, or a refiner's ``.pt``/``.onnx`` file; ``refine_mirror``,
    ``refine_passes``: how it is applied (None: the refiner's defaults,
    :data:`gpr3d.detection.refine.MIRROR` and :data:`~gpr3d.detection.refine.PASSES`); ``box_rule``: the
    label rule of a refiner with several heads (``"auto"``: P-GPR's for pictures, gpr3d's for recordings);
    ``quality_weight``: how much a refiner's quality head rescales the scores (None: as the refiner says for
    each rule, :meth:`~gpr3d.detection.refine.BoxRefiner.weight_for`; 0: not at all); ``fine_refiner``: the
    refiner's fine stage (:attr:`~gpr3d.detection.refine.BoxRefiner.fine`: ``"auto"`` the shipped one with the
    shipped refiner, ``"none"``, or a file).
    """
    from gpr3d.detection.refine import MIRROR, PASSES, check_application, check_quality_weight, check_rule

    mirror, passes = check_application(MIRROR if refine_mirror is None else refine_mirror,
                                       PASSES if refine_passes is None else refine_passes)
    box_rule = check_rule(box_rule)
    quality_weight = check_quality_weight(quality_weight)
    det = _load_network(path, device=device, engine=engine)
    if refiner == "auto":
        refiner = "default" if path is None else None
    if refiner not in (None, "none"):
        from gpr3d.detection.refine import load_refiner

        onnx = det.model is None  # the ONNX engine: no PyTorch for the refiner either
        det.refiner = load_refiner(None if refiner == "default" else refiner, engine="onnx" if onnx else "torch",
                                   mirror=mirror, passes=passes, rule=box_rule, quality_weight=quality_weight,
                                   fine=fine_refiner)
    return det


def fastest_engine(path=None, device: str = "cpu") -> str:
    """The engine that runs detector ``path`` fastest where speed comes first (live mode): ``"int8"`` for the
    shipped model on the CPU where ONNX Runtime and the 8-bit graph are installed, else ``"auto"``."""
    from importlib.util import find_spec

    from gpr3d.detection.ort import DEFAULT_INT8

    if path is None and str(device) == "cpu" and DEFAULT_INT8.is_file() and find_spec("onnxruntime"):
        return "int8"
    return "auto"


def _load_network(path, *, device: str, engine: str) -> "Detector":
    from gpr3d.core.errors import GPR3DError

    if engine not in ENGINES:
        raise GPR3DError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")
    is_onnx = path is not None and str(path).lower().endswith(".onnx")
    if engine == "auto":
        if is_onnx:
            engine = "onnx"
        elif path is None and str(device) == "cpu":
            from importlib.util import find_spec

            from gpr3d.detection.ort import DEFAULT_ONNX

            engine = "onnx" if DEFAULT_ONNX.is_file() and find_spec("onnxruntime") else "torch"
        else:
            engine = "torch"
    if engine == "int8":
        if path is not None:
            raise GPR3DError(f"--runtime int8 runs the shipped detector's 8-bit graph; for {path} make one with "
                             "python references/detection/quantize_onnx.py OUT.onnx and run it with --runtime onnx")
        from gpr3d.detection.ort import DEFAULT_INT8, OnnxDetector

        return OnnxDetector.load(DEFAULT_INT8, device=device)
    if engine == "onnx":
        if path is not None and not is_onnx:
            raise GPR3DError(f"--runtime onnx needs an .onnx file (export one with "
                             f"python references/detection/export_onnx.py {path} OUT.onnx), not {path}")
        from gpr3d.detection.ort import OnnxDetector

        return OnnxDetector.load(path, device=device)
    if is_onnx:
        raise GPR3DError(f"{path} is an ONNX export: run it with --runtime onnx (or auto)")
    return Detector.load(path, device=device)


#: the formats of real radars' recordings and of pictures: a refiner's quality leaves their scores as the network
#: gives them unless a weight is given (measured to help on simulated records only: on the embedded 400 MHz DZT at
#: weight 1 none of its three boxes kept score 0.5, and P-GPR's real pictures lost 0.015 mAP@[.5:.95])
REAL_FORMATS = ("dzt", "dt1", "rd3", "segy", "picture")


def _kept(kinds, boxes, scores, labels, shares, probs=None):
    """One window's network output as float64 arrays ``(boxes, scores, labels, shares, probs)``; a one-class
    network's label-1 boxes only. ``probs`` (a row a box, a column a kind): every kind's share; a network that gives
    none (an ONNX graph exported before it did) has its best kind's share there and 0 for the others."""
    labels = np.asarray(labels, dtype=np.int64)
    keep = labels == 1 if not kinds else (labels >= 1) & (labels <= len(kinds))
    shares = np.ones(len(labels)) if shares is None else np.asarray(shares, dtype=np.float64)
    if probs is None:
        probs = np.zeros((len(labels), len(kinds) if kinds else 1))
        probs[np.nonzero(keep)[0], labels[keep] - 1] = shares[keep]
    probs = np.asarray(probs, np.float64).reshape(len(labels), len(kinds) if kinds else 1)
    return (np.asarray(boxes, np.float64)[keep], np.asarray(scores, np.float64)[keep], labels[keep], shares[keep],
            probs[keep])


class Detector:
    """A trained detector with its window settings."""

    nms = None  #: None: torchvision's non-maximum suppression when merging windows
    #: a :class:`~gpr3d.detection.refine.BoxRefiner` that moves the merged boxes onto a label rule (None: the network's)
    refiner = None
    #: test-time views: the record is also detected stretched along its traces by each of these factors (old
    #: trace ``i`` at column ``i * factor``: 2 shows a hyperbola twice as wide), and with ``mirror`` its traces
    #: reversed too; all views' boxes are mapped back to the record and fused. ``(1.0,)`` and no mirror: one view
    trace_scales: tuple = (1.0,)
    mirror = False
    vote = False  #: a fused box's score: its group's scores summed over the views (at most 1); else the best's
    #: how many traces wide the training records' features were (:func:`~gpr3d.detection.windows.trace_width`,
    #: their median): what a trace scale of ``"auto"`` stretches each record to; None: unknown
    reference_width = None
    fuse_average = True  #: the fused views' boxes: the score-weighted mean of each group's corners (else the best's)
    #: other networks run on the same windows (an ensemble: :meth:`set_members`); each one's boxes are one more view,
    #: fused as the views are (with ``vote``, a box's score is its group's mean over the views)
    members: tuple = ()
    #: a refined box overlapping a surer one by this IoU or more has its score lowered as a duplicate
    #: (:func:`~gpr3d.detection.windows.soften_duplicates`); None: the refined boxes keep their scores
    duplicate_iou = DUPLICATE_IOU

    def __init__(self, model, window: WindowConfig, *, provenance: dict | None = None, device: str = "cpu",
                 batch: int = 8):
        self.model, self.window, self.provenance, self.device, self.batch = model, window, provenance or {}, device, batch
        self.reference_width = self.provenance.get("trace_width")  # a fine-tune's real pictures (finetune_pgpr.py)
        from gpr3d.detection.calibration import check_calibration

        #: the Platt map its scores go through (:mod:`gpr3d.detection.calibration`); None: the network's own
        self.calibration = check_calibration(self.provenance.get("score_calibration"),
                                             f"{self.provenance.get('name', 'detector')}: score_calibration")

    @classmethod
    def load(cls, path=None, *, device: str = "cpu") -> "Detector":
        from gpr3d.detection.weights import load_weights

        model, window, prov = load_weights(path, device=device)
        return cls(model, window, provenance=prov, device=device)

    @property
    def kinds(self) -> list[str] | None:
        """The target kinds the network names (label ``k + 1`` is ``kinds[k]``); ``None``: one class."""
        return getattr(self.model, "gpr3d_kinds", None)

    def _refine_settings(self, survey) -> dict:
        """How the refiner was applied to ``survey``: mirror, passes, the name of its fine stage (None: none), the
        overlap from which a refined box's score is lowered as a surer one's duplicate
        (:func:`~gpr3d.detection.windows.soften_duplicates`) and, where the refiner has them, the label rule of the
        head it used and its quality head's weight on the scores."""
        r = self.refiner
        out = {"mirror": bool(r.mirror), "passes": int(r.passes),
               "fine": None if r.fine_for(survey) is None else r.fine.provenance.get("name", "fine stage"),
               "duplicate_iou": self.duplicate_iou}
        if r.rules:
            out["rule"] = r.head_for(survey)[1]
        if r.quality:
            out["quality_weight"] = self._quality_weight(survey)
        return out

    def _quality_weight(self, survey) -> float | None:
        """The power of the refiner's quality on ``survey``'s scores: the refiner's (:meth:`BoxRefiner.weight_for`),
        except 0 for a real recording or a picture (:data:`REAL_FORMATS`) where no weight was given."""
        r = self.refiner
        if r.quality and r.quality_weight is None and (getattr(survey, "metadata", None) or {}).get("format") \
                in REAL_FORMATS:
            return 0.0
        return r.weight_for(survey)

    def share_cores(self) -> None:
        """Leave the cores to other work between runs: the ONNX engine's threads stop spinning
        (:meth:`gpr3d.detection.ort.OnnxDetector.share_cores`); nothing to change here."""

    def predict_windows(self, images: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Raw network output per window image ``(3, rows, traces)``: ``(boxes px (k, 4), scores (k,))``."""
        return [(b, s) for b, s, *_ in self.predict_windows_kinds(images)]

    def predict_windows_kinds(self, images: list[np.ndarray]) -> list[tuple]:
        """Per window ``(boxes px (k, 4), scores (k,), labels (k,), kind shares (k,), every kind's share (k, kinds))``.

        One-class networks: only label 1 (hyperbola) is kept and every share is 1.
        """
        torch = require("torch")
        out = []
        self.model.eval()
        with torch.inference_mode():
            for i in range(0, len(images), self.batch):
                batch = [torch.from_numpy(np.ascontiguousarray(im)).to(self.device) for im in images[i : i + self.batch]]
                for r in self.model(batch):
                    out.append(_kept(self.kinds, r["boxes"].cpu().numpy(), r["scores"].cpu().numpy(),
                                     r["labels"].cpu().numpy(),
                                     r["kind_scores"].cpu().numpy() if "kind_scores" in r else None,
                                     r["kind_probs"].cpu().numpy() if "kind_probs" in r else None))
        return out

    def set_members(self, members) -> None:
        """Run these detectors' networks too, on the same windows (an ensemble): each one's boxes are fused with this
        one's as another view of the record (``vote``: a fused box scores its group's mean over the networks and
        views). The members must read the same windows and name the same kinds; one line naming the first that
        does not."""
        members = tuple(members)
        for k, m in enumerate(members, 1):
            if not callable(getattr(m, "predict_windows_kinds", None)):
                raise InvalidDataError(f"ensemble member {k}: not a detector ({type(m).__name__})")
            if m.window != self.window:
                raise InvalidDataError(f"ensemble member {k} ({m.provenance.get('name', 'gpr3d detector')}): its windows "
                                       f"({m.window}) differ from the detector's ({self.window})")
            if m.kinds != self.kinds:
                raise InvalidDataError(f"ensemble member {k} ({m.provenance.get('name', 'gpr3d detector')}): it names the "
                                       f"kinds {m.kinds}, the detector {self.kinds}")
        self.members = members

    def _view(self, survey, proc: np.ndarray | None, factor: float, mirror: bool):
        """One view of the record (``proc``, made here where None, stretched along its traces by ``factor``: old
        trace ``i`` at ``i * factor``; with ``mirror``, its traces reversed): ``(parts, window count, proc)``, a part
        for each network (this one, then :attr:`members`), each its merged boxes in the record's traces and seconds,
        their scores, labels, kind shares and every kind's share."""
        from gpr3d.detection.augment import stretch_traces

        with stage("windows"):
            if proc is None:
                proc = prepare(survey, self.window)
            n = proc.shape[0]
            if factor == "auto":
                factor = self.auto_scale(proc)
            view = proc[::-1] if mirror else proc
            if factor < 1.0:  # squeezed: each column the mean of the traces it stands for (no aliasing), centred
                view = running_mean(view, int(round(1.0 / factor)) | 1, axis=0)
            if factor != 1.0:
                view = stretch_traces(view, factor)
            wins = windows(survey, self.window, processed=np.ascontiguousarray(view))
        parts = []
        for net in (self, *self.members):
            with stage("network"):
                raw = net.predict_windows_kinds([w.image for w in wins])
                # (a subclass's four items, without every kind's share: the named kind's alone)
                raw = [r if len(r) > 4 else _kept(self.kinds, *r) for r in raw]
            with stage("merge"):
                boxes, scores, index = merge([(w, b, s) for w, (b, s, *_) in zip(wins, raw)], view.shape[0],
                                             survey.dt_s, nms=self.nms, return_index=True)
            labels = np.concatenate([r[2] for r in raw])[index] if raw else np.zeros(0, np.int64)
            shares = np.concatenate([r[3] for r in raw])[index] if raw else np.zeros(0)
            probs = (np.concatenate([r[4] for r in raw])[index] if raw
                     else np.zeros((0, len(self.kinds) if self.kinds else 1)))
            boxes = np.asarray(boxes, float).reshape(-1, 4).copy()
            boxes[:, [0, 2]] /= factor
            if mirror:
                boxes[:, [0, 2]] = (n - 1.0) - boxes[:, [2, 0]]
            parts.append((boxes, np.asarray(scores, float), labels, shares, probs))
        return parts, len(wins), proc

    def auto_scale(self, proc: np.ndarray) -> float:
        """The stretch that makes a processed record's features as wide as the training records' were:
        ``reference_width / trace_width(proc)``, kept within 0.25..4."""
        return float(np.clip(self.reference_width / trace_width(proc), 0.25, 4.0))

    def _views(self, survey):
        """The record seen as it is and, where ``trace_scales``/``mirror`` ask, stretched along its traces and
        mirrored; the views' boxes in one set, overlapping ones (IoU >= 0.5, time in samples) merged into the
        best-scored one, whose corners become the score-weighted mean of the group's (see ``trace_scales``).
        Returns ``(plain, proc, boxes, scores, labels, shares, probs, n_windows)``: ``proc`` the record as the
        network sees it, ``plain`` the same before its rows are equalised."""
        if "auto" in self.trace_scales and not self.reference_width:
            raise InvalidDataError("trace scale 'auto' needs the width of the detector's training records "
                                   "(Detector.reference_width, traces); this detector has none")
        views = [(f if f == "auto" else float(f), m) for f in self.trace_scales
                 for m in ((False, True) if self.mirror else (False,))]
        with stage("prepare"):
            plain = prepare(survey, replace(self.window, equalise=False))
            proc = equalise_rows(plain) if self.window.equalise else plain
        parts, n_windows = [], 0
        for f, m in views:
            got, n, _ = self._view(survey, proc, f, m)
            parts += got
            n_windows += n
        if len(parts) == 1:
            return (plain, proc, *parts[0], n_windows)
        with stage("merge"):
            boxes = np.concatenate([p[0] for p in parts])
            scores = np.concatenate([p[1] for p in parts])
            labels = np.concatenate([p[2] for p in parts]).astype(np.int64)
            shares = np.concatenate([np.asarray(p[3], float) for p in parts])
            probs = np.concatenate([np.asarray(p[4], float) for p in parts])
            if self.vote:
                keep, fused, fscores = fuse_views(boxes, scores, survey.dt_s, average=self.fuse_average,
                                                  n_views=len(parts))
            else:
                keep, fused = fuse_views(boxes, scores, survey.dt_s, average=self.fuse_average)
                fscores = scores[keep]
        return plain, proc, fused, fscores, labels[keep], shares[keep], probs[keep], n_windows

    def detect(self, survey, *, score_threshold: float = 0.5, input_name: str | None = None) -> dict:
        """Detections of one record as the ``gpr3d detect`` contract (CONVENTIONS.md)."""
        if not 0.0 <= score_threshold <= 1.0:
            raise InvalidDataError(f"score threshold must lie in 0..1, got {score_threshold!r}")
        t0 = time.perf_counter()
        plain, proc, boxes, scores, labels, shares, probs, n_windows = self._views(survey)
        if self.calibration is not None:  # (increasing: the boxes' order stays; the threshold keeps calibrated ones)
            from gpr3d.detection.calibration import calibrate

            scores = calibrate(scores, self.calibration)
        if self.refiner is not None and len(boxes):
            with stage("refine"):
                from gpr3d.detection.refine import record_image

                # only the boxes reported: each box is refined on its own, the others' moves would be thrown away
                sure = np.nonzero(np.asarray(scores, float) >= score_threshold)[0]
                boxes = np.array(boxes, float).reshape(-1, 4)
                if len(sure):
                    w = self._quality_weight(survey) or 0.0
                    boxes[sure], q = self.refiner.refine_scored(survey, self.window.rows, boxes[sure],
                                                                record_image(proc, self.window.style), score=w > 0)
                    scores = np.array(scores, float)  # (a copy: the scores below are the refined boxes')
                    if q is not None:  # the quality head's IoU rescales the scores of the boxes it moved
                        scores[sure] = scores[sure] * np.clip(q, 0.0, 1.0) ** w
                    if self.duplicate_iou is not None:  # two boxes moved onto one hyperbola: the less sure ranks lower
                        scores[sure] = soften_duplicates(boxes[sure], scores[sure], survey.dt_s,
                                                         iou=self.duplicate_iou)
        with stage("apexes"):
            kinds = self.kinds
            s_per_row = rows_interval(survey, self.window)
            # apexes from ``plain``: data whose rows keep the pulse's shape (equalising the rows distorts it)
            t_end = (survey.n_samples - 1) * survey.dt_s
            kept = []
            for j in np.argsort(-np.asarray(scores, float), kind="stable"):
                b, s = boxes[j], scores[j]
                b = [float(np.clip(b[0], 0, survey.n_traces - 1)), float(np.clip(b[1], 0, t_end)),
                     float(np.clip(b[2], 0, survey.n_traces - 1)), float(np.clip(b[3], 0, t_end))]
                if s >= score_threshold and b[2] > b[0] and b[3] > b[1]:
                    kind = kinds[int(labels[j]) - 1] if kinds else "target"
                    kept.append((b, s, kind, float(shares[j]) if kinds else None, boxes[j], probs[j]))
            # cut boxes take their width from the record's whole ones (one wave speed, one trace step)
            rate = width_rate([b for b, s, *_ in kept if s >= 0.5], survey.n_traces, t_end, survey.frequency_hz)
            targets = []
            whole = self.refiner is not None and getattr(self.refiner, "whole", False)
            if whole:
                from gpr3d.detection.refine import whole_apex
            for b, s, kind, share, raw, pr in kept:
                at, att = apex_of_box(plain, b, s_per_row, frequency_hz=survey.frequency_hz, n_traces=survey.n_traces,
                                      width_per_s=rate)
                if whole:  # a refiner of whole hyperbolas reaches past the record's end: the apex is its centre
                    wa = whole_apex(raw, survey.n_traces)
                    at = at if wa is None else wa
                t = {"box": b, "score": float(s), "apex_trace": int(round(at)), "apex_time_s": float(att),
                     "kind": kind, "kind_score": share}
                if kinds:
                    t["kind_shares"] = {k: round(float(p), 4) for k, p in zip(kinds, pr)}
                if survey.positions_xyz is not None and survey.distances_m is not None:
                    t["x_m"] = float(np.interp(at, np.arange(survey.n_traces), survey.distances_m))
                targets.append(t)
        return {"input": input_name or survey.metadata.get("path"), "channel": survey.metadata.get("channel", 0),
                "n_traces": survey.n_traces, "dt_s": survey.dt_s, "n_windows": n_windows,
                "detector": self.provenance.get("name", "gpr3d detector"),
                "refiner": None if self.refiner is None else self.refiner.provenance.get("name", "gpr3d box refiner"),
                "refine": None if self.refiner is None else self._refine_settings(survey),
                "views": {"trace_scales": [f if f == "auto" else float(f) for f in self.trace_scales],
                          "mirror": bool(self.mirror)},
                "members": [m.provenance.get("name", "gpr3d detector") for m in self.members],
                "score_threshold": score_threshold, "calibrated": self.calibration is not None,
                "wall_s": time.perf_counter() - t0, "targets": targets}
