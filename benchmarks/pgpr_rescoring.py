"""Rescoring P-GPR's detections by how well their boxes fit (issue 29): can the refiner's own features, read by a
logistic model fitted to the shipped detector's boxes on P-GPR *train*, rank the boxes that fit their labels above
those that do not, better than the detector's score does?

    python benchmarks/pgpr_rescoring.py [--pgpr DIR] [--weights 0.5 1 2] [--out DIR] [--cache DIR]

For every picture of P-GPR train and val the shipped detector's boxes (every score) are refined by the shipped
refiner (P-GPR's head) and the refiner's penultimate features (256 numbers) are read at its last look at each refined
box, as it reads its quality there (both mirror looks). A logistic model (L-BFGS, L2 1e-3) of those features
predicts each train box's IoU with its nearest label (soft targets); with ``+ score`` the logit of the detector's
score is one more input. Rows on val: the detector's score alone (as shipped), score x q^W for the refiner's quality
head and for the fitted models, and two oracles that know the labels (score x true IoU, true IoU). Class-averaged
metrics as ``gpr3d.detection.evaluate`` scores them (each box under its kind at its score, under the other kinds at
score x share). The dumped boxes are kept in ``--cache`` (a re-run reads them; delete it after a model changes).
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from _report import cpu_name, write_table  # noqa: E402


def feature_look(net, seen: list):
    """The refiner ``net``'s outputs for a batch of crops, as ``_refined`` asks for them, with its penultimate
    features (one row a crop) appended to ``seen`` at every look."""
    import numpy as np
    import torch

    def look(c):
        with torch.inference_mode():
            f = net[:-1](torch.from_numpy(np.ascontiguousarray(c, np.float32)))
            seen.append(f.numpy().copy())
            return net[-1](f).numpy().astype(float)
    return look


def dump(det, records) -> list[dict]:
    """Per record: refined boxes (traces, seconds; cut to the record), scores, kind shares, the refiner's quality
    and features at each refined box (rows: the boxes, then their mirror looks), the labels and their kinds."""
    import numpy as np

    from gpr3d.detection.refine import _refined, check_application, record_image

    ref = det.refiner
    net = ref.net.eval()
    mirror, passes = check_application(ref.mirror, ref.passes)
    out = []
    for survey, lab in records:
        _, proc, boxes, scores, _, _, probs, _ = det._views(survey)
        boxes = np.asarray(boxes, float).reshape(-1, 4)
        seen = []
        look = feature_look(net, seen)
        head, _ = ref.head_for(survey)
        rb, q = _refined(survey, det.window.rows, boxes, record_image(proc, det.window.style), look, mirror=mirror,
                         passes=passes, head=head, quality=True, score=True)
        t_end = (survey.n_samples - 1) * survey.dt_s
        rb[:, [0, 2]] = np.clip(rb[:, [0, 2]], 0, survey.n_traces - 1)
        rb[:, [1, 3]] = np.clip(rb[:, [1, 3]], 0, t_end)
        out.append({"dt": survey.dt_s, "boxes": rb, "scores": np.asarray(scores, float), "probs": probs, "q": q,
                    "feats": seen[-1] if len(boxes) else np.zeros((0, 256), np.float32),
                    "labels": np.array([x["box"] for x in lab["labels"]], float).reshape(-1, 4),
                    "kinds": [x["kind"] for x in lab["labels"]]})
    return out


def with_iou(recs: list[dict]) -> list[dict]:
    """Each record's boxes and labels in traces and samples, and each box's IoU with its nearest label."""
    import numpy as np

    from gpr3d.detection.refine import best_iou

    for r in recs:
        px = np.array([1, 1 / r["dt"], 1, 1 / r["dt"]])
        r["bpx"], r["gpx"] = r["boxes"] * px, r["labels"] * px
        r["iou"] = best_iou(r["bpx"], r["gpx"])
    return recs


def metrics(recs, kinds, scores) -> dict:
    """Class-averaged metrics (each box under its kind at its score, under the others at score x share) and the
    class-agnostic mAP@[.5:.95] of ``scores`` (one array a record)."""
    import numpy as np

    from gpr3d.detection.evaluate import coco_metrics, kind_rows

    boxes, sc, names = [], [], []
    for r, s in zip(recs, scores):
        rows = [(b, score, kind) for b, x, p in zip(r["bpx"], s, r["probs"])
                for kind, score in kind_rows({"score": x, "kind": kinds[int(np.argmax(p))],
                                              "kind_shares": dict(zip(kinds, p))})]
        boxes.append(np.array([x[0] for x in rows], float).reshape(-1, 4))
        sc.append(np.array([x[1] for x in rows], float))
        names.append([x[2] for x in rows])
    m = coco_metrics([r["gpx"] for r in recs], boxes, sc, gt_kinds=[r["kinds"] for r in recs], det_kinds=names,
                     kinds=kinds)
    m["agnostic"] = coco_metrics([r["gpx"] for r in recs], [r["bpx"] for r in recs], scores)["mAP"]
    return m


def ranking_table(rows, kinds, echo: bool = False) -> list[str]:
    """The markdown table of ``rows`` (``(name, records, scores per record)``): class-averaged mAP@0.5, @0.75,
    @[.5:.95], AR@100, recall@0.5 and class-agnostic mAP@[.5:.95] of each ranking (each row printed as it comes
    with ``echo``)."""
    lines = ["| ranking | class-averaged mAP@0.5 | mAP@0.75 | mAP@[.5:.95] | AR@100 | recall@0.5 | class-agnostic "
             "mAP@[.5:.95] |", "|---|---|---|---|---|---|---|"]
    for name, recs, scores in rows:
        m = metrics(recs, kinds, scores)
        lines.append(f"| {name} | {m['mAP@0.5']:.3f} | {m['mAP@0.75']:.3f} | {m['mAP']:.3f} | {m['AR@100']:.3f} | "
                     f"{m['recall@0.5']:.3f} | {m['agnostic']:.3f} |")
        if echo:
            print(lines[-1], flush=True)
    return lines


def fit(recs, *, with_score: bool, l2: float = 1e-3):
    """A logistic model of each box's IoU from its features (and its score's logit): a function of a record
    giving each box's predicted IoU (the mean over its two mirror looks)."""
    import numpy as np
    import torch

    def inputs(r):
        x = torch.from_numpy(np.asarray(r["feats"], np.float32))
        if with_score:
            s = np.clip(np.tile(r["scores"], 2), 1e-4, 1 - 1e-4)
            x = torch.cat([x, torch.from_numpy(np.log(s / (1 - s)).astype(np.float32))[:, None]], 1)
        return x

    x = torch.cat([inputs(r) for r in recs])
    y = torch.from_numpy(np.concatenate([np.tile(r["iou"], 2) for r in recs]).astype(np.float32))
    mu, sd = x.mean(0), x.std(0) + 1e-6
    torch.manual_seed(0)
    lin = torch.nn.Linear(x.shape[1], 1)
    opt = torch.optim.LBFGS(lin.parameters(), max_iter=300, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        loss = torch.nn.functional.binary_cross_entropy_with_logits(lin((x - mu) / sd)[:, 0], y)
        loss = loss + l2 * (lin.weight ** 2).sum()
        loss.backward()
        return loss

    opt.step(closure)

    def predict(r):
        with torch.inference_mode():
            p = torch.sigmoid(lin((inputs(r) - mu) / sd)[:, 0]).numpy()
        k = len(r["boxes"])
        return 0.5 * (p[:k] + p[k:])
    return predict


def parser(script: str, doc: str) -> argparse.ArgumentParser:
    """The P-GPR rescoring scripts' parser, with its ``--pgpr`` folder (see :func:`add_outputs`, :func:`check_pgpr`)."""
    from eval_pgpr import PGPR_DEFAULT

    p = argparse.ArgumentParser(prog=f"{script}.py", description=doc,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--pgpr", default=str(PGPR_DEFAULT), help="P-GPR folder (train/ and val/)")
    return p


def add_outputs(p: argparse.ArgumentParser, script: str) -> None:
    """``--out``, ``--name`` (``SCRIPT.md``) and ``--cache`` (``build/SCRIPT``, where the dumped boxes are kept)."""
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    p.add_argument("--name", default=f"{script}.md")
    p.add_argument("--cache", default=str(ROOT / "build" / script), help="where the dumped boxes are kept")


def check_pgpr(p: argparse.ArgumentParser, folder) -> None:
    """One line from ``p`` where ``folder`` lacks P-GPR's train/ or val/."""
    for part in ("train", "val"):
        if not (Path(folder) / part).is_dir():
            p.error(f"--pgpr {folder}: no {part}/ folder in it (P-GPR's train/ and val/)")


def main(argv=None) -> None:
    from eval_pgpr import pgpr_records

    p = parser("pgpr_rescoring", __doc__)
    p.add_argument("--weights", nargs="+", type=float, default=[0.5, 1.0, 2.0], metavar="W",
                   help="the powers W of score x q^W tried (0..8)")
    add_outputs(p, "pgpr_rescoring")
    args = p.parse_args(argv)
    if any(not 0 <= w <= 8 for w in args.weights):
        p.error(f"--weights must lie in 0..8, got {' '.join(f'{w:g}' for w in args.weights)}")
    check_pgpr(p, args.pgpr)
    import numpy as np

    from gpr3d.detection.infer import load_detector

    det = load_detector(refiner="default", engine="torch")
    if not det.refiner.quality:
        p.error("the shipped refiner has no quality head")
    data, t0 = {}, time.perf_counter()
    for part in ("train", "val"):
        cache = Path(args.cache) / f"{part}.pkl"
        if cache.is_file():
            data[part] = pickle.loads(cache.read_bytes())
        else:
            data[part] = dump(det, pgpr_records(args.pgpr, part))
            cache.parent.mkdir(parents=True, exist_ok=True)
            tmp = cache.with_suffix(".part")
            tmp.write_bytes(pickle.dumps(data[part]))
            tmp.replace(cache)
        with_iou(data[part])
    dump_s = time.perf_counter() - t0
    kinds = det.kinds
    train, val = data["train"], data["val"]
    probe, probe_s = fit(train, with_score=False), fit(train, with_score=True)
    rows = [("train: score (the detector has seen these pictures)", train, [r["scores"] for r in train]),
            ("val: score (as shipped)", val, [r["scores"] for r in val])]
    for w in args.weights:
        rows.append((f"val: score x quality head^{w:g}", val, [r["scores"] * np.clip(r["q"], 0, 1) ** w for r in val]))
    for w in args.weights:
        rows.append((f"val: score x features' fit^{w:g}", val, [r["scores"] * probe(r) ** w for r in val]))
    rows.append(("val: features + score's fit alone", val, [probe_s(r) for r in val]))
    for w in args.weights:
        rows.append((f"val: score x (features + score)'s fit^{w:g}", val, [r["scores"] * probe_s(r) ** w for r in val]))
    rows += [("val oracle: score x true IoU", val, [r["scores"] * r["iou"] for r in val]),
             ("val oracle: true IoU", val, [r["iou"] for r in val])]
    n_train, n_val = (sum(len(r["boxes"]) for r in d) for d in (train, val))
    share = [float(np.mean(np.concatenate([r["iou"] for r in d]) >= 0.5)) for d in (train, val)]
    lines = [f"P-GPR: the shipped detector and refiner's boxes at every score, train {len(train)} pictures ({n_train} "
             f"boxes, {share[0]:.0%} at IoU >= 0.5), val {len(val)} ({n_val} boxes, {share[1]:.0%}); host CPU "
             f"{cpu_name()}; dumping {dump_s:.0f} s", ""] + ranking_table(rows, kinds)
    write_table(args.out, args.name, "\n".join(lines), "pgpr_rescoring.py", argv)


if __name__ == "__main__":
    main()
