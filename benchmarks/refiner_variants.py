"""The refiners an evaluation measures: each named refiner once, one with a quality head once per quality weight."""

from __future__ import annotations


def refiner_variants(refiners, weights) -> list[tuple[str, float | None]]:
    """``(refiner spec, quality weight or None)`` for each of ``refiners`` ('default' or a file): a refiner
    with a quality head once per weight of ``weights`` ("own": None, the weight the refiner gives each rule; else a
    number in 0..8, each checked), any other once with None. Each file is opened here, before any work: one that
    is not a refiner, or a weight that is not one, is one line (``GPR3DError``)."""
    from gpr3d.core.errors import InvalidDataError
    from gpr3d.detection.refine import check_quality_weight, load_refiner

    ws = []
    for w in weights:
        try:
            ws.append(None if w == "own" else check_quality_weight(float(w)))
        except ValueError:
            raise InvalidDataError(f"--quality-weights: {w!r} is neither own nor a number in 0..8") from None
    out = []
    for r in refiners:
        quality = load_refiner(None if r == "default" else r).quality
        out += [(r, w) for w in ws] if quality else [(r, None)]
    return out
