"""Permittivity and depth estimates of a record: fit, network and their combination against known truth."""

import math

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import C0
from gpr3d.inversion.estimate import FIT_MODEL_ERROR, depth_from_apex, estimate_depths
from tests.inversion.test_depthnet import hyperbola_record


@pytest.mark.parametrize("eps, depth, h", [(9.0, 0.3, 0.0), (4.0, 1.2, 0.5), (20.0, 0.05, 0.06)])
def test_depth_from_apex_inverts_the_bistatic_travel_time(eps, depth, h):
    v = C0 / math.sqrt(eps)
    t = 1e-9 + 2 * math.hypot(depth, h / 2) / v
    assert depth_from_apex(t, 1e-9, eps, h) == pytest.approx(depth, abs=1e-9)
    assert math.isnan(depth_from_apex(0.5e-9, 1e-9, eps, h))  # before time zero: no depth


class FixedNet:
    """A stand-in for DepthNet with known outputs (the combination is what is tested here)."""

    def __init__(self, eps, sigma, depth):
        self.eps, self.sigma, self.depth = eps, sigma, depth

    def estimate(self, survey, boxes, trace_spacing_m=None):
        return {"eps_r": self.eps, "sigma_eps_r": self.sigma, "n_windows": len(boxes),
                "depth_m": [self.depth] * len(boxes)}


def _record():
    s, lab = hyperbola_record(spacing=0.01, eps=9.0, depth=0.3, x0=1.0, length=2.0)
    return s, lab["labels"]


def test_the_fit_alone_gives_the_point_diffractor_back():
    s, targets = _record()
    r = estimate_depths(s, targets, method="fit")
    assert r["permittivity"]["eps_r"] == pytest.approx(9.0, rel=0.02)
    assert r["targets"][0]["depth_m"] == pytest.approx(0.3, abs=0.005)
    assert r["targets"][0]["x_m"] == pytest.approx(1.0, abs=1e-6)


def test_hybrid_weighs_network_and_fit_by_their_uncertainties_and_takes_depth_from_the_apex():
    s, targets = _record()
    fit = estimate_depths(s, targets, method="fit")["permittivity"]
    net = FixedNet(eps=12.0, sigma=1.0, depth=0.9)
    r = estimate_depths(s, targets, method="hybrid", estimator=net)
    p = r["permittivity"]
    s_fit = math.hypot(fit["sigma_eps_r"], FIT_MODEL_ERROR * fit["eps_r"])
    w1, w2 = 1 / 1.0**2, 1 / s_fit**2
    assert p["eps_r"] == pytest.approx((w1 * 12.0 + w2 * fit["eps_r"]) / (w1 + w2), rel=1e-9)
    assert p["sigma_eps_r"] == pytest.approx(1 / math.sqrt(w1 + w2), rel=1e-9)
    assert fit["eps_r"] < p["eps_r"] < 12.0
    # depth from the data's apex time with that eps_r: 0.3 m scaled by sqrt(9 / eps)
    assert r["targets"][0]["depth_m"] == pytest.approx(0.3 * math.sqrt(9.0 / p["eps_r"]), rel=0.02)
    assert r["targets"][0]["depth_m_net"] == 0.9
    # the network alone: its own numbers
    n = estimate_depths(s, targets, method="net", estimator=net)
    assert n["permittivity"]["eps_r"] == 12.0 and n["targets"][0]["depth_m"] == 0.9


def test_unknown_method_is_refused():
    s, targets = _record()
    with pytest.raises(InvalidDataError, match="unknown depth method"):
        estimate_depths(s, targets, method="magic")


def test_evaluation_scores_records_once_for_eps_and_every_target_for_depth():
    from gpr3d.inversion.evaluate import _stats, depth_table

    rows = [{"record": 0, "method": "fit", "kind": "rebar", "depth_true": 0.1, "eps_true": 8.0, "eps": 10.0,
             "depth": 0.12},
            {"record": 0, "method": "fit", "kind": "pvc", "depth_true": 0.5, "eps_true": 8.0, "eps": 10.0,
             "depth": 0.45},
            {"record": 1, "method": "fit", "kind": "rebar", "depth_true": 0.2, "eps_true": 4.0, "eps": 4.0,
             "depth": float("nan")}]
    n, k, mae, mape, dmae, drel = _stats(rows)
    assert (n, k) == (3, 2)
    assert mae == pytest.approx(2.0) and mape == pytest.approx(0.25)  # record 1 has no finite depth: not scored
    assert dmae == pytest.approx((0.02 + 0.05) / 2)
    assert drel == pytest.approx((0.2 + 0.1) / 2)
    table = "\n".join(depth_table(rows))
    assert "| fit | top 0-0.3 m | 2 | 1 |" in table and "| fit | pvc | 1 | 1 |" in table
