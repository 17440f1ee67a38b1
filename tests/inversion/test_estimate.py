"""Permittivity and depth estimates of a record: fit, network and their combination against known truth."""

import math

import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.inversion.estimate import FIT_BIAS, FIT_MODEL_ERROR, estimate_depths
from tests.inversion.test_depthnet import hyperbola_record


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


def test_hybrid_refines_the_network_with_the_bias_corrected_fit_only_where_they_agree():
    s, targets = _record()
    fit = estimate_depths(s, targets, method="fit")["permittivity"]
    fc = fit["eps_r"] / (1 + FIT_BIAS)  # the point diffractor's fit is exact: ~9 / 0.872
    assert fc == pytest.approx(9.0 / (1 + FIT_BIAS), rel=0.02)
    net = FixedNet(eps=11.0, sigma=1.0, depth=0.9)
    r = estimate_depths(s, targets, method="hybrid", estimator=net)
    p = r["permittivity"]
    assert p["fit_agrees"] is True  # |10.3 - 11| < 2 sigma
    w1, w2 = 1.0, 1 / math.hypot(fit["sigma_eps_r"] / (1 + FIT_BIAS), FIT_MODEL_ERROR * fc) ** 2
    assert p["eps_r"] == pytest.approx((w1 * 11.0 + w2 * fc) / (w1 + w2), rel=1e-9, abs=0)
    assert p["sigma_eps_r"] == pytest.approx(1 / math.sqrt(w1 + w2), rel=1e-9, abs=0)
    # the network's depth rescaled to the refined eps_r (same travel time)
    assert r["targets"][0]["depth_m"] == pytest.approx(0.9 * math.sqrt(11.0 / p["eps_r"]), rel=1e-9, abs=0)
    assert r["targets"][0]["depth_m_net"] == 0.9
    # a fit far from the network (more than two of its sigmas) is left out
    far = estimate_depths(s, targets, method="hybrid", estimator=FixedNet(eps=20.0, sigma=1.0, depth=0.5))
    assert far["permittivity"]["fit_agrees"] is False
    assert far["permittivity"]["eps_r"] == 20.0 and far["targets"][0]["depth_m"] == 0.5
    # the network alone: its own numbers
    n = estimate_depths(s, targets, method="net", estimator=net)
    assert n["permittivity"]["eps_r"] == 11.0 and n["targets"][0]["depth_m"] == 0.9


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
