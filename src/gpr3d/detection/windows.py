"""From any Survey to detector windows and back.

:func:`prepare` applies the standard processing (dewow, removal of the mean trace,
a depth-equalising gain) without moving time zero, so that rows keep counting
from the first recorded sample (CONVENTIONS.md). :func:`windows` cuts the record
into blocks of ``traces`` traces with ``overlap``, each resampled to ``rows`` rows
over the whole time window, and :func:`render` makes the network's 3-channel
image of a block: the signed amplitude, its envelope, and the amplitude after a
time-power gain (or the reference paper's 'hot' colouring, ``style="hot"``).
:func:`merge` maps window boxes back to traces and seconds and removes the
duplicates of overlapping windows; :func:`apex_of_box` finds the top of the
hyperbola inside a box.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from gpr3d.core.deps import require
from gpr3d.core.errors import InvalidDataError
from gpr3d.io.coco import BOX_PAD_PERIODS, PixelMap
from gpr3d.processing.analytic import hilbert_envelope, running_mean
from gpr3d.processing.image import network_view, record_scale, render_channels as render

__all__ = ["WindowConfig", "Window", "prepare", "windows", "make_window", "record_scale", "rows_interval", "render",
           "width_rate",
           "merge", "fuse_views", "soften_duplicates", "DUPLICATE_IOU", "trace_width", "apex_of_box", "window_targets"]


@dataclass
class WindowConfig:
    """How a record becomes detector windows.

    Attributes
    ----------
    traces : int
        Traces per window (one image column each), 16..4096.
    rows : int
        Image rows (the record's whole time window, resampled), 32..2048.
    overlap : float
        Fraction of a window shared with the next, 0..0.9.
    style : {"channels", "hot"}
        ``channels``: signed, envelope and gained channels; ``hot``: the reference paper's colouring.
    dewow, background : bool
        Remove the wow and the mean trace before rendering.
    equalise : bool
        Divide each row by its RMS across the record (deep echoes as bright as shallow ones).

    Raises
    ------
    InvalidDataError
        A value outside its range, in one line naming it.
    """

    traces: int = 256  #: traces per window (one image column each)
    rows: int = 256  #: image rows (the record's whole time window, resampled)
    overlap: float = 0.5  #: fraction of a window shared with the next
    style: str = "channels"  #: "channels" (signed, envelope, gained) or "hot" (the reference's colouring)
    dewow: bool = True
    background: bool = True
    equalise: bool = True  #: divide each row by its RMS across the record (deep echoes as bright as shallow)

    def __post_init__(self):
        if not (isinstance(self.traces, int) and 16 <= self.traces <= 4096):
            raise InvalidDataError(f"window traces must be an integer in 16..4096, got {self.traces!r}")
        if not (isinstance(self.rows, int) and 32 <= self.rows <= 2048):
            raise InvalidDataError(f"window rows must be an integer in 32..2048, got {self.rows!r}")
        if not (0.0 <= float(self.overlap) <= 0.9):
            raise InvalidDataError(f"window overlap must lie in 0..0.9, got {self.overlap!r}")
        if self.style not in ("channels", "hot"):
            raise InvalidDataError(f"window style must be 'channels' or 'hot', got {self.style!r}")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class Window:
    """One block of a record: ``image (3, rows, traces)`` float32 and its :class:`~gpr3d.io.coco.PixelMap`."""

    image: np.ndarray
    pixmap: PixelMap
    trace_start: int
    n_traces: int  #: real traces in the block (the rest is padding)


def prepare(survey, cfg: WindowConfig | None = None) -> np.ndarray:
    """Processed data ``(n_traces, rows)`` float32 of a record: the detector's view of it
    (:func:`gpr3d.processing.image.network_view` with the window's settings)."""
    cfg = cfg or WindowConfig()
    return network_view(survey, cfg.rows, dewow=cfg.dewow, background=cfg.background, equalise=cfg.equalise)


def make_window(processed: np.ndarray, start: int, cfg: WindowConfig, s_per_row: float, scale: float) -> Window:
    """The window of ``cfg.traces`` traces from ``start`` (zero-padded past the record's end), rendered."""
    block = processed[start : start + cfg.traces]
    real = block.shape[0]
    if real < cfg.traces:
        block = np.concatenate([block, np.zeros((cfg.traces - real, processed.shape[1]), np.float32)])
    # column c shows trace start + c, row r time r * s_per_row (pixel centres at +0.5)
    pm = PixelMap(trace0=start - 0.5, traces_per_px=1.0, t0_s=-0.5 * s_per_row, s_per_px=s_per_row)
    return Window(render(block, cfg.style, scale=scale), pm, start, real)


def rows_interval(survey, cfg: WindowConfig) -> float:
    """Seconds per image row: the whole record resampled to ``cfg.rows`` rows."""
    return (survey.n_samples - 1) * survey.dt_s / (cfg.rows - 1)


def windows(survey, cfg: WindowConfig | None = None, *, processed: np.ndarray | None = None) -> list[Window]:
    """The record's windows, left to right; the last one ends at the last trace; short records are padded."""
    cfg = cfg or WindowConfig()
    proc = prepare(survey, cfg) if processed is None else processed
    n = proc.shape[0]
    step = max(1, int(round(cfg.traces * (1 - cfg.overlap))))
    starts = list(range(0, max(n - cfg.traces, 0) + 1, step))
    if starts[-1] + cfg.traces < n:
        starts.append(n - cfg.traces)
    spr, scale = rows_interval(survey, cfg), record_scale(proc)
    return [make_window(proc, s0, cfg, spr, scale) for s0 in starts]


def window_targets(labels: list[dict], win: Window, *, min_inside: float = 0.6, return_kinds: bool = False):
    """Boxes ``(k, 4)`` in window pixels of the visible labels whose apex lies in the window.

    A box cut by the window's edge is kept (clipped) when at least ``min_inside`` of
    its width is inside; otherwise it is left out. With ``return_kinds`` also the
    kept labels' kinds (a list, ``"target"`` where a label names none).
    """
    kinds = []
    w = win.image.shape[2]
    h = win.image.shape[1]
    out = []
    for lab in labels:
        if not lab.get("visible", True):
            continue
        x0, y0, x1, y1 = win.pixmap.box_to_px(lab["box"])
        ax, _ = win.pixmap.point_to_px(lab["apex_trace"], lab["apex_time_s"])
        if not (0 <= ax <= win.n_traces):
            continue
        cx0, cx1 = max(x0, 0.0), min(x1, float(win.n_traces))
        if (cx1 - cx0) < min_inside * max(x1 - x0, 1e-9):
            continue
        cy0, cy1 = max(y0, 0.0), min(y1, float(h))
        if cy1 - cy0 < 1 or cx1 - cx0 < 1:
            continue
        out.append([cx0, cy0, min(cx1, w), cy1])
        kinds.append(lab.get("kind", "target"))
    boxes = np.asarray(out, dtype=np.float32).reshape(-1, 4)
    return (boxes, kinds) if return_kinds else boxes


def merge(per_window: list[tuple[Window, np.ndarray, np.ndarray]], n_traces: int, dt_s: float, *,
          iou: float = 0.5, edge_px: float = 2.0, nms=None, return_index: bool = False):
    """Window detections -> record boxes ``(k, 4)`` [trace_start, t_start_s, trace_end, t_end_s] and scores.

    A box that touches a window's inner edge (not the record's) is cut by it: its
    score is lowered so that the same hyperbola seen whole in the overlapping window
    wins; duplicates are removed by non-maximum suppression in record coordinates
    (time in samples, so that IoU does not depend on units): torchvision's, or ``nms``
    (``nms(boxes, scores, iou) -> kept indices``, e.g. ONNX Runtime's in
    :func:`gpr3d.detection.ort.onnx_nms`). With ``return_index`` a third item: the kept
    boxes' places in the windows' boxes taken in order (to carry what else they hold).
    """

    boxes, scores, ranks = [], [], []
    for win, b, s in per_window:
        for bb, ss in zip(np.asarray(b, float).reshape(-1, 4), np.asarray(s, float).reshape(-1)):
            rec = win.pixmap.px_to_box(bb)
            cut = (bb[0] <= edge_px and win.trace_start > 0) or \
                  (bb[2] >= win.n_traces - edge_px and win.trace_start + win.n_traces < n_traces)
            rec[0], rec[2] = max(rec[0], 0.0), min(rec[2], n_traces - 1.0)
            boxes.append(rec)
            scores.append(float(ss))
            ranks.append(float(ss) * (0.5 if cut else 1.0))
    if not boxes:
        return (np.zeros((0, 4)), np.zeros(0)) + ((np.zeros(0, np.int64),) if return_index else ())
    boxes_a = np.asarray(boxes)
    scaled = boxes_a.copy()
    scaled[:, [1, 3]] /= dt_s
    if nms is None:
        torch = require("torch")
        from torchvision.ops import nms as tv_nms

        keep = tv_nms(torch.as_tensor(scaled), torch.as_tensor(np.asarray(ranks)), iou).numpy()
    else:
        keep = np.asarray(nms(scaled, np.asarray(ranks), iou), dtype=np.int64)
    if return_index:
        return boxes_a[keep], np.asarray(scores)[keep], keep
    return boxes_a[keep], np.asarray(scores)[keep]


def trace_width(processed: np.ndarray) -> float:
    """How many traces wide a record's features are: the lag (traces, linearly interpolated) where the
    autocorrelation along the traces, summed over the rows, first falls to half its value at lag 0.

    ``processed`` is ``(n_traces, rows)`` (:func:`prepare`'s view); each row's mean is removed first. A radar with a
    denser trace interval shows the same hyperbolas wider: its width is larger (P-GPR's two radars: a median of
    about 23 and 11 traces). A record with no lateral variation, or none that decays, gives ``n_traces``.
    """
    x = np.asarray(processed, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 2:
        raise InvalidDataError(f"a record of shape {x.shape} has no width along its traces")
    x = x - x.mean(axis=0, keepdims=True)
    n = x.shape[0]
    spec = np.fft.rfft(x, n=2 * n, axis=0)
    ac = np.fft.irfft((spec * spec.conj()).real, n=2 * n, axis=0)[:n].sum(axis=1)
    if not ac[0] > 0:
        return float(n)
    ac = ac / ac[0]
    below = np.nonzero(ac < 0.5)[0]
    if not below.size:
        return float(n)
    k = int(below[0])
    return float(k - 1 + (ac[k - 1] - 0.5) / (ac[k - 1] - ac[k]))


def _overlaps(sc: np.ndarray, area: np.ndarray, i: int) -> np.ndarray:
    """IoU of box ``i`` of ``sc`` (``(k, 4)``, one unit per axis) with every box of it (``area``: their areas)."""
    w = np.maximum(np.minimum(sc[i, 2], sc[:, 2]) - np.maximum(sc[i, 0], sc[:, 0]), 0)
    h = np.maximum(np.minimum(sc[i, 3], sc[:, 3]) - np.maximum(sc[i, 1], sc[:, 1]), 0)
    inter = w * h
    union = area[i] + area - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def _in_samples(boxes, scores, dt_s: float):
    """Checked ``(boxes in traces and samples, their areas, scores)`` of boxes in traces and seconds."""
    b = np.asarray(boxes, float).reshape(-1, 4)
    s = np.asarray(scores, float).reshape(-1)
    if len(b) != len(s):
        raise InvalidDataError(f"{len(b)} boxes but {len(s)} scores")
    if isinstance(dt_s, bool) or not (isinstance(dt_s, (int, float, np.integer, np.floating))
                                      and math.isfinite(dt_s) and dt_s > 0):
        raise InvalidDataError(f"the sample interval must be a positive number of seconds, got {dt_s!r}")
    sc = b.copy()
    sc[:, [1, 3]] /= dt_s
    area = np.maximum(sc[:, 2] - sc[:, 0], 0) * np.maximum(sc[:, 3] - sc[:, 1], 0)
    return sc, area, s


#: overlap (IoU, time in samples) from which a refined box counts as a surer one's duplicate: the merge's own
DUPLICATE_IOU = 0.5


def soften_duplicates(boxes, scores, dt_s: float, *, iou: float = DUPLICATE_IOU) -> np.ndarray:
    """The scores of a record's refined boxes (``(k, 4)`` in traces and seconds), a duplicate's lowered.

    :func:`merge` leaves no two boxes overlapping by ``iou`` or more, but a box refiner moves each box on its own, and
    two boxes on one hyperbola (its whole and a part, or two of its sizes) can end on nearly the same place. In order
    of score, each box whose largest overlap ``o`` (IoU, time in samples) with a surer box reaches ``iou`` has its
    score multiplied by ``1 - o`` (linear soft-NMS, Bodla et al. 2017, in one pass: the overlaps are taken with the
    scores as given). The box stays, lower in the ranking, so that where it fits the hyperbola better than the
    surer one it still counts at strict IoU; a caller's threshold may drop it. Ties keep the boxes' order.
    """
    if not 0.0 < iou <= 1.0:
        raise InvalidDataError(f"the duplicates' overlap must lie in (0, 1], got {iou!r}")
    sc, area, s = _in_samples(boxes, scores, dt_s)
    out = s.copy()
    order = np.argsort(-s, kind="stable")
    for n, i in enumerate(order[1:], start=1):
        o = float(_overlaps(sc, area, i)[order[:n]].max())
        if o >= iou:
            out[i] = s[i] * (1.0 - o)
    return out


def fuse_views(boxes, scores, dt_s: float, *, iou: float = 0.5, average: bool = True, n_views: int | None = None):
    """Boxes of several views of one record (``(k, 4)`` in traces and seconds) fused: ``(kept indices, boxes)``,
    and with ``n_views`` a third item, the fused scores: each group's scores summed over ``n_views`` (at most 1),
    so that a box the views agree on ranks above one that a single view saw.

    In order of score, each box not yet taken gathers every untaken box that overlaps it by ``iou`` or more (time
    in samples, as :func:`merge`); it is kept with the group's corners averaged, weighted by score (``average``;
    otherwise its own), and the rest of the group is dropped. The kept indices carry scores, kinds and the like.
    """
    b = np.asarray(boxes, float).reshape(-1, 4)
    sc, area, s = _in_samples(b, scores, dt_s)
    if not len(b):
        return (np.zeros(0, np.int64), np.zeros((0, 4))) + ((np.zeros(0),) if n_views else ())
    free = np.ones(len(b), bool)
    keep, out, fs = [], [], []
    for i in np.argsort(-s, kind="stable"):
        if not free[i]:
            continue
        ov = _overlaps(sc, area, i)
        group = free & (ov >= iou)
        group[i] = True
        free &= ~group
        keep.append(i)
        wt = s[group] if average and s[group].sum() > 0 else None
        out.append(np.average(b[group], axis=0, weights=wt) if average else b[i])
        fs.append(min(1.0, float(s[group].sum()) / n_views) if n_views else s[i])
    res = np.asarray(keep, np.int64), np.asarray(out, float).reshape(-1, 4)
    return res + ((np.asarray(fs, float),) if n_views else ())


def width_rate(boxes, n_traces: int, t_end_s: float, frequency_hz: float | None) -> float | None:
    """Traces of box width per second of box height beyond the two pads, from the record's whole boxes.

    Under the label rule (``docs/labels.md``) a box reaches ``(depth + radius) tan 45 deg``
    either side of the apex and down to the arrival there, so its width over its height
    less ``2 BOX_PAD_PERIODS / f`` is ``v tan(45) / (dx (1 / cos(45) - 1))`` for every target
    of one record, whatever its depth and radius (one wave speed ``v``, one trace step
    ``dx``). The median over the boxes that neither edge of the record nor its end cuts;
    ``None`` when there are none or the frequency is unknown.
    """
    if not frequency_hz:
        return None
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    pad2 = 2 * BOX_PAD_PERIODS / frequency_hz
    h = b[:, 3] - b[:, 1] - pad2
    whole = (b[:, 0] > 0.5) & (b[:, 2] < n_traces - 1.5) & (b[:, 3] < 0.99 * t_end_s) & (h > 0.2 * pad2)
    if not whole.any():
        return None
    return float(np.median((b[whole, 2] - b[whole, 0]) / h[whole]))


def apex_of_box(processed: np.ndarray, box, s_per_row: float, *, frequency_hz: float | None = None,
                n_traces: int | None = None, width_per_s: float | None = None) -> tuple[float, float]:
    """Apex ``(trace, time_s)`` of the hyperbola in ``box`` (times from the first sample).

    Boxes follow the label rule (``docs/labels.md``): symmetric about the apex in
    traces, their top ``BOX_PAD_PERIODS / f`` before the apex. So the apex trace is
    the box's centre, unless the box is cut by the record's first or last trace.
    Then, given the record's ``width_per_s`` (:func:`width_rate`), the box's height
    gives its whole width, and the apex lies half of it in from the uncut side;
    without it (or for a box cut on both sides, or by the record's end), the apex
    is the trace of earliest strong arrival (envelope above half its box maximum).
    The apex time is the box top plus the pad when the antenna frequency is known,
    else the envelope peak on the apex trace in the box's upper part.
    """
    i0, ta, i1, tb = (float(v) for v in box)
    n, rows = processed.shape
    n_traces = n if n_traces is None else n_traces
    left, right = i0 <= 0.5, i1 >= n_traces - 1.5
    if width_per_s and frequency_hz and left != right and tb < 0.99 * (rows - 1) * s_per_row:
        half = 0.5 * width_per_s * max(tb - ta - 2 * BOX_PAD_PERIODS / frequency_hz, 0.0)
        trace = float(np.clip(i1 - half if left else i0 + half, 0, n_traces - 1))
        return trace, ta + BOX_PAD_PERIODS / frequency_hz
    c0, c1 = int(np.clip(np.floor(i0), 0, n - 1)), int(np.clip(np.ceil(i1), 0, n - 1))
    r0, r1 = int(np.clip(np.floor(ta / s_per_row), 0, rows - 1)), int(np.clip(np.ceil(tb / s_per_row), 0, rows - 1))
    trace = 0.5 * (i0 + i1)
    env = None
    if c1 >= c0 and r1 > r0:
        env = hilbert_envelope(processed[c0 : c1 + 1].astype(np.float64), axis=1)[:, r0 : r1 + 1]
    if (left or right) and env is not None and env.max() > 0:
        top = env[:, : max(2, (env.shape[1] + 1) // 2)]
        strong = top >= 0.5 * top.max()
        first = np.where(strong.any(axis=1), np.argmax(strong, axis=1), top.shape[1] + 5).astype(float)
        smooth = running_mean(first, max(1, min(5, first.size // 4 or 1)))
        cand = np.nonzero(smooth <= smooth.min() + 0.5)[0]
        trace = float(c0 + cand[len(cand) // 2])
    if frequency_hz:
        return trace, ta + BOX_PAD_PERIODS / frequency_hz
    if env is None:
        return trace, ta
    col = env[int(np.clip(round(trace) - c0, 0, env.shape[0] - 1)), : max(2, (env.shape[1] + 1) // 2)]
    j = int(np.argmax(col))
    y = float(j)
    if 0 < j < col.size - 1:  # parabolic sub-row refinement
        den = col[j - 1] - 2 * col[j] + col[j + 1]
        if den < 0:
            y += 0.5 * (col[j - 1] - col[j + 1]) / den
    return trace, (r0 + y) * s_per_row
