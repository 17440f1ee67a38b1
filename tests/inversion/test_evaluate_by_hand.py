"""gpr3d eval depth's bookkeeping by hand: which targets are judged, one eps_r per record, the groups and the table,
with estimate_depths replaced by a stand-in whose answers are set here."""

import math

import pytest

import gpr3d.inversion.evaluate as ev


def _labels(eps, targets):
    return {"eps_r": eps, "labels": [dict(kind=k, depth_m=d, box=[0, 0, 1, 1], **({"visible": v} if v is not None
                                                                                  else {}))
                                     for k, d, v in targets]}


@pytest.fixture
def answers(monkeypatch):
    """estimate_depths answers eps = 10 x method index + record's first depth, depths = truth + 0.01 per method."""
    calls = []

    def fake(survey, targets, *, method, estimator=None):
        calls.append((survey, [t["depth_m"] for t in targets], method, estimator))
        k = ev.METHODS.index(method)
        return {"permittivity": {"eps_r": 10.0 * k + targets[0]["depth_m"]},
                "targets": [{"depth_m": t["depth_m"] + 0.01 * (k + 1)} for t in targets]}

    monkeypatch.setattr(ev, "estimate_depths", fake)
    return calls


def test_depth_rows_judge_the_visible_targets_of_every_record_with_every_method(answers):
    records = [("rec A", _labels(6.0, [("rebar", 0.1, True), ("void", 0.4, False), ("pvc_pipe", 1.5, None)])),
               ("rec B", _labels(9.0, [("tank", 0.9, False)])),  # nothing visible: skipped
               ("rec C", _labels(4.0, [("steel_pipe", 0.25, True)]))]
    rows = ev.depth_rows(records, estimator="NET", methods=("fit", "net"))
    assert [(c[0], c[1], c[2], c[3]) for c in answers] == [("rec A", [0.1, 1.5], "fit", "NET"),
                                                           ("rec A", [0.1, 1.5], "net", "NET"),
                                                           ("rec C", [0.25], "fit", "NET"),
                                                           ("rec C", [0.25], "net", "NET")]
    kf, kn = ev.METHODS.index("fit"), ev.METHODS.index("net")
    assert rows == [
        {"record": 0, "method": "fit", "kind": "rebar", "depth_true": 0.1, "eps_true": 6.0, "eps": 10.0 * kf + 0.1,
         "depth": 0.1 + 0.01 * (kf + 1)},
        {"record": 0, "method": "fit", "kind": "pvc_pipe", "depth_true": 1.5, "eps_true": 6.0, "eps": 10.0 * kf + 0.1,
         "depth": 1.5 + 0.01 * (kf + 1)},
        {"record": 0, "method": "net", "kind": "rebar", "depth_true": 0.1, "eps_true": 6.0, "eps": 10.0 * kn + 0.1,
         "depth": 0.1 + 0.01 * (kn + 1)},
        {"record": 0, "method": "net", "kind": "pvc_pipe", "depth_true": 1.5, "eps_true": 6.0, "eps": 10.0 * kn + 0.1,
         "depth": 1.5 + 0.01 * (kn + 1)},
        {"record": 2, "method": "fit", "kind": "steel_pipe", "depth_true": 0.25, "eps_true": 4.0,
         "eps": 10.0 * kf + 0.25, "depth": 0.25 + 0.01 * (kf + 1)},
        {"record": 2, "method": "net", "kind": "steel_pipe", "depth_true": 0.25, "eps_true": 4.0,
         "eps": 10.0 * kn + 0.25, "depth": 0.25 + 0.01 * (kn + 1)},
    ]
    assert ev.depth_rows(records[:1], estimator=None)[0]["method"] == ev.METHODS[0]  # all methods by default
    assert [c[2] for c in answers[-3:]] == list(ev.METHODS)


def _row(record, method, kind, dt, et, e, d):
    return {"record": record, "method": method, "kind": kind, "depth_true": dt, "eps_true": et, "eps": e, "depth": d}


def test_stats_by_hand():
    rows = [_row(0, "fit", "rebar", 0.1, 8.0, 10.0, 0.12), _row(0, "fit", "void", 0.0005, 8.0, 10.0, 0.0025),
            _row(1, "fit", "rebar", 0.2, 4.0, 3.0, 0.2), _row(2, "fit", "tank", 0.5, 5.0, float("nan"), 0.5)]
    n, k, mae, mape, dmae, drel = ev._stats(rows)
    assert (n, k) == (4, 3)  # record 2 has no eps: not scored at all
    assert mae == pytest.approx((2.0 + 1.0) / 2, rel=1e-12, abs=0)  # records 0 and 1 once each
    assert mape == pytest.approx((0.25 + 0.25) / 2, rel=1e-12, abs=0)
    assert dmae == pytest.approx((0.02 + 0.002 + 0.0) / 3, rel=1e-12, abs=0)
    # the relative error of a target at 0.5 mm is taken against 1 mm (no division by ~0)
    assert drel == pytest.approx((0.2 + 2.0 + 0.0) / 3, rel=1e-12, abs=0)
    assert ev._stats([_row(0, "fit", "x", 0.1, 4.0, 4.0, float("inf"))])[:2] == (1, 0)
    n, k, *rest = ev._stats([])
    assert (n, k) == (0, 0) and all(math.isnan(v) for v in rest)


def test_the_table_lists_every_method_then_all_depth_ranges_then_kinds():
    rows = [_row(0, "net", "rebar", 0.1, 8.0, 10.0, 0.12), _row(0, "net", "void", 0.3, 8.0, 10.0, 0.25),
            _row(0, "net", "tank", 1.0, 8.0, 10.0, 1.2), _row(1, "net", "rebar", 0.29, 4.0, 5.0, 0.29),
            _row(0, "fit", "rebar", 0.1, 8.0, 8.0, 0.1)]
    table = ev.depth_table(rows)
    assert table[:2] == ["| method | targets | n | estimated | eps_r MAE | eps_r MAPE | depth MAE m | depth rel. "
                         "error |", "|---|---|---|---|---|---|---|---|"]
    # METHODS order (hybrid, net, fit): no hybrid rows, so net first; ranges 0-0.3 (0.1, 0.29), 0.3-1 (0.3),
    # > 1 (1.0: the upper bound is open); kinds in alphabetical order
    assert table[2:] == [
        "| net | all | 4 | 4 | 1.500 | 25.0 % | 0.0675 | 14.2 % |",  # (0.02 + 0.05 + 0.2 + 0) / 4
        "| net | top 0-0.3 m | 2 | 2 | 1.500 | 25.0 % | 0.0100 | 10.0 % |",
        "| net | top 0.3-1 m | 1 | 1 | 2.000 | 25.0 % | 0.0500 | 16.7 % |",
        "| net | top > 1 m | 1 | 1 | 2.000 | 25.0 % | 0.2000 | 20.0 % |",
        "| net | rebar | 2 | 2 | 1.500 | 25.0 % | 0.0100 | 10.0 % |",
        "| net | tank | 1 | 1 | 2.000 | 25.0 % | 0.2000 | 20.0 % |",
        "| net | void | 1 | 1 | 2.000 | 25.0 % | 0.0500 | 16.7 % |",
        "| fit | all | 1 | 1 | 0.000 | 0.0 % | 0.0000 | 0.0 % |",
        "| fit | top 0-0.3 m | 1 | 1 | 0.000 | 0.0 % | 0.0000 | 0.0 % |",
        "| fit | rebar | 1 | 1 | 0.000 | 0.0 % | 0.0000 | 0.0 % |",
    ]
    assert ev.DEPTH_RANGES == ((0.0, 0.3), (0.3, 1.0), (1.0, math.inf))
