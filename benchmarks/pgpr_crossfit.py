"""Rescoring P-GPR's detections with a model fitted to boxes that look like val's (issue 29, cross-fitting).

    python benchmarks/pgpr_crossfit.py --folds runs/fold_even/weights.pt runs/fold_odd/weights.pt [--out DIR]

``pgpr_rescoring.py`` fitted its rescorer to the shipped detector's boxes on P-GPR *train*, pictures the detector
was fine-tuned on, whose boxes fit far better than val's: the fit did not carry over. Here the training boxes come
from two *fold* detectors (``references/detection/finetune_pgpr.py --init STAGE3 --only '*[02468].png'`` and
``'*[13579].png'``: the synthetic-only stage-3 model fine-tuned on one half of P-GPR train), each run on the half it
has not seen, so their mistakes are the kind val's are. Every detector runs as ``eval_pgpr.py`` runs the shipped one
(score 0, the shipped refiner with its fine stage and duplicate softening).

Each box is described by what the pipeline knows without labels: the logit of its score, its kind shares, its size
and place in the picture (log width in traces, log height in ns, top and bottom as shares of the record), how much it
overlaps the boxes scored above it in the same picture (largest IoU, how many at IoU >= 0.3), its rank and its
score against the picture's best, the refiner's quality estimate at the final box and (``--features``) the refiner's
256 penultimate features there. Its target is the IoU it gets credit for: boxes are matched greedily by score to
labels (IoU >= 0.5 each label once), a box that takes a label is worth its IoU, any other (a duplicate, a poor or a
background box) 0. A small MLP (or ``--linear``: a logistic model) of the standardised inputs predicts it; its output
(or the score times it to a power) ranks val's boxes.

Rows: val as shipped; val rescored by the model fitted to the folds' boxes (its prediction as the score, the score
times it to a power, or each picture's own score values handed out again in the order of the prediction: boxes
reordered, the values a threshold sees per picture kept; also fitted without the refiner's quality estimate); val rescored by a model fitted on val
itself, two-fold by picture (a diagnostic of what such features can give at best with val-like boxes: each half
rescored by the model fitted on the other half; NOT a figure to quote for the shipped model); the label-aware oracles.
The dumps are kept in ``--cache`` (a re-run reads them; delete it after a model changes).
"""

from __future__ import annotations

import hashlib
import pickle
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402


def dump(det, records, threshold: float = 0.0) -> list[dict]:
    """Per record: the detector's final boxes at or above ``threshold`` (seconds, cut to the record), scores, kind
    shares, and the refiner's quality and penultimate features at each final box (the mean of its two mirror looks),
    the labels."""
    import numpy as np

    from pgpr_rescoring import feature_look

    from gpr3d.detection.refine import _refined, record_image
    from gpr3d.detection.windows import prepare

    ref = det.refiner
    net = ref.net.eval()
    kinds = det.kinds
    out = []
    for survey, lab in records:
        res = det.detect(survey, score_threshold=threshold)
        tg = res["targets"]
        boxes = np.array([t["box"] for t in tg], float).reshape(-1, 4)
        probs = np.array([[t["kind_shares"][k] for k in kinds] for t in tg], float).reshape(-1, len(kinds))
        seen = []
        look = feature_look(net, seen)
        head, _ = ref.head_for(survey)
        proc = prepare(survey, det.window)
        _, q = _refined(survey, det.window.rows, boxes, record_image(proc, det.window.style), look, mirror=True,
                        passes=0, head=head, quality=True, score=True)
        feats = (0.5 * (seen[-1][: len(boxes)] + seen[-1][len(boxes):]) if len(boxes)
                 else np.zeros((0, 256), np.float32))
        out.append({"name": Path(lab["image"]).name, "dt": survey.dt_s, "n_traces": survey.n_traces,
                    "n_samples": survey.n_samples, "boxes": boxes, "scores": np.array([t["score"] for t in tg], float),
                    "probs": probs, "q": np.asarray(q, float), "feats": np.asarray(feats, np.float32),
                    "labels": np.array([x["box"] for x in lab["labels"]], float).reshape(-1, 4),
                    "kinds": [x["kind"] for x in lab["labels"]]})
    return out


def credited(bpx, gpx, scores, thr: float = 0.5):
    """Each box's IoU with the label it takes when boxes are matched greedily by score (each label once, at IoU >=
    ``thr``); 0 for a box that takes none."""
    import numpy as np

    from gpr3d.detection.refine import pair_iou

    out = np.zeros(len(bpx))
    if not len(bpx) or not len(gpx):
        return out
    iou = pair_iou(bpx[:, None, :], gpx[None, :, :])
    free = np.ones(len(gpx), bool)
    for i in np.argsort(-scores, kind="stable"):
        cand = np.where(free, iou[i], -1.0)
        j = int(np.argmax(cand))
        if cand[j] >= thr:
            free[j] = False
            out[i] = iou[i, j]
    return out


def prepare_records(recs):
    """Boxes and labels in traces and samples; each box's IoU with its nearest label and the IoU it is credited."""
    import numpy as np

    from gpr3d.detection.refine import best_iou

    for r in recs:
        px = np.array([1, 1 / r["dt"], 1, 1 / r["dt"]])
        r["bpx"], r["gpx"] = r["boxes"] * px, r["labels"] * px
        r["iou"] = best_iou(r["bpx"], r["gpx"])
        r["credit"] = credited(r["bpx"], r["gpx"], r["scores"])
    return recs


def hand_features(r, quality: bool = True):
    """The label-free description of each box of a record (see the module's text); ``quality`` False: the
    refiner's quality estimate left out (a column of zeros: ``gpr3d detect`` does not compute it for pictures)."""
    import numpy as np

    from gpr3d.detection.refine import pair_iou

    b, s = r["bpx"], np.clip(r["scores"], 1e-4, 1 - 1e-4)
    n = len(b)
    if not n:  # (as many columns as a record with boxes gives: 11 and one a kind)
        return np.zeros((0, 11 + r["probs"].shape[1]))
    w = np.maximum(b[:, 2] - b[:, 0], 1e-3)
    h = np.maximum(b[:, 3] - b[:, 1], 1e-3) * r["dt"] * 1e9
    order = np.argsort(-s, kind="stable")
    rank = np.empty(n)
    rank[order] = np.arange(n)
    iou = pair_iou(b[:, None, :], b[None, :, :])
    above = s[None, :] > s[:, None]  # [i, j]: box j scored above box i
    over = np.where(above, iou, 0.0)
    return np.column_stack([np.log(s / (1 - s)), r["probs"], np.log(w), np.log(h), r["bpx"][:, 1] / r["n_samples"],
                            r["bpx"][:, 3] / r["n_samples"], over.max(1), (over >= 0.3).sum(1),
                            np.log1p(rank), s / s.max(), np.clip(r["q"], 0, 1) if quality else np.zeros(n),
                            np.full(n, np.log(n))])


def inputs(r, with_feats: bool, quality: bool = True):
    import numpy as np

    x = hand_features(r, quality)
    return np.hstack([x, r["feats"]]) if with_feats else x


def fit(recs, *, with_feats: bool, linear: bool, seed: int = 0, epochs: int = 300, quality: bool = True):
    """A model of each box's credited IoU from its inputs: a function of a record giving each box's prediction."""
    import numpy as np
    import torch

    x = torch.from_numpy(np.vstack([inputs(r, with_feats, quality) for r in recs]).astype(np.float32))
    y = torch.from_numpy(np.concatenate([r["credit"] for r in recs]).astype(np.float32))
    mu, sd = x.mean(0), x.std(0) + 1e-6
    torch.manual_seed(seed)
    d = x.shape[1]
    net = torch.nn.Linear(d, 1) if linear else torch.nn.Sequential(
        torch.nn.Linear(d, 32), torch.nn.ReLU(), torch.nn.Dropout(0.2), torch.nn.Linear(32, 1))
    opt = torch.optim.AdamW(net.parameters(), lr=3e-3, weight_decay=1e-2)
    xs = (x - mu) / sd
    net.train()
    for _ in range(epochs):
        opt.zero_grad()
        loss = torch.nn.functional.binary_cross_entropy_with_logits(net(xs)[:, 0], y)
        loss.backward()
        opt.step()
    net.eval()

    def predict(r):
        if not len(r["bpx"]):
            return np.zeros(0)
        with torch.inference_mode():
            z = torch.from_numpy(inputs(r, with_feats, quality).astype(np.float32))
            return torch.sigmoid(net((z - mu) / sd)[:, 0]).numpy().astype(float)
    return predict


def rank_mapped(scores, prediction):
    """A picture's own score values handed out again in the order of ``prediction`` (the highest score to the box
    predicted best, ...): the boxes are reordered, the values a threshold sees in the picture stay the same."""
    import numpy as np

    scores = np.asarray(scores, float)
    out = np.empty_like(scores)
    out[np.argsort(-np.asarray(prediction, float), kind="stable")] = np.sort(scores)[::-1]
    return out


def cached(path: Path, make):
    if path.is_file():
        return pickle.loads(path.read_bytes())
    data = make()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part")
    tmp.write_bytes(pickle.dumps(data))
    tmp.replace(path)
    return data


def main(argv=None) -> None:
    from eval_pgpr import load, pgpr_records
    from pgpr_rescoring import add_outputs, check_pgpr, parser, ranking_table

    p = parser("pgpr_crossfit", __doc__)
    p.add_argument("--folds", nargs=2, metavar=("EVEN", "ODD"), default=None,
                   help="weights of the detectors fine-tuned on P-GPR train's even- and odd-numbered pictures")
    p.add_argument("--fold-refiners", nargs=4, metavar=("EVEN", "EVEN_FINE", "ODD", "ODD_FINE"), default=None,
                   help="box refiners (and their fine stages) trained on the same halves of P-GPR train as --folds "
                        "(references/detection/train_refiner.py --only): the folds' boxes then owe nothing to the "
                        "labels of the pictures they are on (the shipped refiner was trained on all of P-GPR train)")
    p.add_argument("--powers", nargs="+", type=float, default=[1.0], metavar="W",
                   help="rows also rank by score x prediction^W for these W (0..8); the prediction alone always")
    p.add_argument("--seeds", type=int, default=3, help="models fitted from this many seeds, predictions averaged")
    p.add_argument("--threshold", type=float, default=0.0,
                   help="every detector keeps (and refines) only the boxes scored at or above this, as gpr3d detect "
                        "does at its --score (default 0: every box)")
    add_outputs(p, "pgpr_crossfit")
    args = p.parse_args(argv)
    if any(not 0 <= w <= 8 for w in args.powers):
        p.error(f"--powers must lie in 0..8, got {' '.join(f'{w:g}' for w in args.powers)}")
    if not 1 <= args.seeds <= 20:
        p.error(f"--seeds must lie in 1..20, got {args.seeds}")
    if not 0 <= args.threshold < 1:
        p.error(f"--threshold must lie in [0, 1), got {args.threshold:g}")
    check_pgpr(p, args.pgpr)
    if args.fold_refiners and not args.folds:
        p.error("--fold-refiners go with --folds (the detectors whose boxes they refine)")
    for flag, files in (("--folds", args.folds), ("--fold-refiners", args.fold_refiners)):
        for f in files or ():
            if not Path(f).is_file():
                p.error(f"{flag}: no such weights file: {f}")
    import numpy as np

    from gpr3d.detection.refine import load_refiner

    def detector(spec, refiner=None, fine="auto"):
        det = load(spec)[0]
        det.refiner = load_refiner(refiner, fine=fine)
        return det

    def tag(*specs):
        h = hashlib.sha256()
        for spec in specs:
            h.update(b"default" if spec is None or spec == "default" else Path(spec).read_bytes())
        return h.hexdigest()[:12]

    t0 = time.perf_counter()
    cache = Path(args.cache)
    det = detector("default")
    kinds = det.kinds
    at = f"_at{args.threshold:g}" if args.threshold else ""  # (the score-0 dumps keep their names)
    val = prepare_records(cached(cache / f"val_{tag('default')}{at}.pkl",
                                 lambda: dump(det, pgpr_records(args.pgpr, "val"), args.threshold)))
    train = []
    if args.folds:
        refs = args.fold_refiners or [None, "auto", None, "auto"]
        for k, (spec, held) in enumerate(zip(args.folds, ("*[13579].png", "*[02468].png"))):  # the half it has not seen
            ref, fine = refs[2 * k : 2 * k + 2]
            fd = detector(spec, ref, fine)
            train += prepare_records(cached(cache / f"train_{tag(spec, ref, None if fine == 'auto' else fine)}{at}.pkl",
                                            lambda fd=fd, held=held: dump(fd, pgpr_records(args.pgpr, "train", held),
                                                                          args.threshold)))
    dump_s = time.perf_counter() - t0

    def averaged(fitted):
        return lambda r: np.mean([f(r) for f in fitted], axis=0)

    def rescored(name, model, recs, rows):
        rows.append((f"{name}: the prediction alone", recs, [model(r) for r in recs]))
        rows.append((f"{name}: the picture's scores rank-mapped by the prediction", recs,
                     [rank_mapped(r["scores"], model(r)) for r in recs]))
        for w in args.powers:
            rows.append((f"{name}: score x prediction^{w:g}", recs, [r["scores"] * model(r) ** w for r in recs]))

    rows = [("val: score (as shipped)", val, [r["scores"] for r in val])]
    if train:  # how the fold detectors do on the halves they did not see: val's level, or the train pictures'?
        rows.append(("train halves, each by the fold detector that did not see it: score", train,
                     [r["scores"] for r in train]))
    variants = [("hand features, MLP", False, False), ("hand + refiner features, MLP", True, False),
                ("hand features, logistic", False, True)]
    for what, feats, linear, quality in [v + (True,) for v in variants] + [
            ("hand features without the refiner's quality, MLP", False, False, False)]:
        if train and not (feats and args.fold_refiners):  # (other refiners' features: not the shipped one's)
            m = averaged([fit(train, with_feats=feats, linear=linear, seed=s, quality=quality)
                          for s in range(args.seeds)])
            rescored(f"val, fitted to the folds' train boxes ({what})", m, val, rows)
    halves = [[r for r in val if int(Path(r["name"]).stem[-1]) % 2 == k] for k in (0, 1)]
    for what, feats, linear in variants:
        ms = [averaged([fit(h, with_feats=feats, linear=linear, seed=s) for s in range(args.seeds)]) for h in halves]
        pred = {id(r): ms[1 - k](r) for k, h in enumerate(halves) for r in h}
        rows.append((f"diagnostic, val two-fold by picture ({what}): the prediction alone", val,
                     [pred[id(r)] for r in val]))
        for w in args.powers:
            rows.append((f"diagnostic, val two-fold by picture ({what}): score x prediction^{w:g}", val,
                         [r["scores"] * pred[id(r)] ** w for r in val]))
    rows += [("val oracle: score x true IoU", val, [r["scores"] * r["iou"] for r in val]),
             ("val oracle: credited IoU", val, [r["credit"] for r in val])]
    n_train, n_val = (sum(len(r["boxes"]) for r in d) for d in (train, val))
    lines = [f"P-GPR: boxes of the shipped detector and refiner on val ({len(val)} pictures, {n_val} boxes, "
             f"{np.mean(np.concatenate([r['credit'] for r in val]) > 0):.0%} credited)"
             + (f"; of the fold detectors on the train halves they did not see ({len(train)} pictures, {n_train} "
                f"boxes, "
                f"{np.mean(np.concatenate([r['credit'] for r in train]) > 0):.0%} credited)" if train else "")
             + (f"; scores at or above {args.threshold:g} only" if args.threshold else "; every score")
             + f"; host CPU {cpu_name()}; dumping {dump_s:.0f} s", ""] + ranking_table(rows, kinds, echo=True)
    write_table(args.out, args.name, "\n".join(lines), "pgpr_crossfit.py", argv)


if __name__ == "__main__":
    main()
