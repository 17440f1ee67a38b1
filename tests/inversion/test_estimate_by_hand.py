"""estimate_depths' bookkeeping with stand-ins for the network and the fit: each method's eps_r, its uncertainty
and every target's depth worked out by hand (the fit's bias correction and the inverse-variance combination)."""

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

import gpr3d.inversion.hyperbola as hyperbola
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.inversion.estimate import (FIT_BIAS, FIT_BIAS_RADIUS, FIT_MODEL_ERROR, FIT_MODEL_ERROR_RADIUS,
                                      estimate_depths)


class _Net:
    def __init__(self, eps, sig, depths):
        self.eps, self.sig, self.depths, self.calls = eps, sig, depths, []

    def estimate(self, survey, boxes, trace_spacing_m=None):
        assert survey is RECORD
        self.calls.append((boxes, trace_spacing_m))
        return {"eps_r": self.eps, "sigma_eps_r": self.sig, "n_windows": 3, "depth_m": list(self.depths)}


def _fit(ok, eps, depth, sd):
    return SimpleNamespace(ok=ok, eps_r=eps, depth_m=depth, sigma_depth_m=sd, apex_time_s=2e-9, rms_s=1e-11,
                           n_picks=12)


@pytest.fixture
def stubs(monkeypatch):
    """fit_boxes and combine_permittivity replaced: the fit says eps (fit_eps, fit_sigma) from its two targets."""
    seen = {}

    def fit_boxes(survey, boxes, apexes=None, trace_spacing_m=None, model="auto", radius_m=None):  # the real defaults
        assert survey is RECORD
        seen.update(boxes=boxes, apexes=apexes, spacing=trace_spacing_m, model=model, radius_m=radius_m)
        return [_fit(True, 6.1, 0.21, 0.01), _fit(False, float("nan"), float("nan"), float("nan"))]

    monkeypatch.setattr(hyperbola, "fit_boxes", fit_boxes)
    monkeypatch.setattr(hyperbola, "combine_permittivity", lambda fits: (seen.get("fit_eps", 6.1), 0.3, 1))
    return seen


RECORD = Survey(data=np.zeros((41, 64), np.float32), dt_s=0.1e-9, frequency_hz=1e9)


def _record():
    return RECORD


TARGETS = [{"box": [5, 1e-9, 15, 3e-9], "apex_trace": 10.0, "apex_time_s": 2e-9},
           {"box": [20, 1e-9, 33, 3e-9], "apex_trace": 25.5, "apex_time_s": 2.2e-9}]  # apex off the box's middle


def test_the_network_alone(stubs):
    net = _Net(7.0, 0.7, [0.2, 0.35])
    out = estimate_depths(_record(), TARGETS, method="net", estimator=net, trace_spacing_m=0.02)
    assert net.calls == [([[5.0, 1e-9, 15.0, 3e-9], [20.0, 1e-9, 33.0, 3e-9]], 0.02)]
    p = out["permittivity"]
    assert p == {"method": "net", "net": {"eps_r": 7.0, "sigma_eps_r": 0.7, "n_windows": 3}, "eps_r": 7.0,
                 "sigma_eps_r": 0.7}
    t0, t1 = out["targets"]
    assert t0["x_m"] == pytest.approx(0.2) and t1["x_m"] == pytest.approx(0.51)  # apex traces x 2 cm
    assert (t0["depth_m"], t1["depth_m"]) == (0.2, 0.35) and t0["depth_m_net"] == 0.2
    assert t0["sigma_depth_m"] == pytest.approx(0.2 * 0.5 * 0.7 / 7.0) and "fit" not in t0


def test_the_fit_alone(stubs):
    out = estimate_depths(_record(), TARGETS, method="fit", trace_spacing_m=0.02)
    assert stubs["apexes"] == [(10.0, 2e-9), (25.5, 2.2e-9)] and stubs["model"] == "point"
    assert stubs["radius_m"] == [None, None] and stubs["spacing"] == 0.02
    assert stubs["boxes"] == [[5.0, 1e-9, 15.0, 3e-9], [20.0, 1e-9, 33.0, 3e-9]]
    p = out["permittivity"]
    assert p == {"method": "fit", "fit": {"eps_r": 6.1, "sigma_eps_r": 0.3, "n_hyperbolas": 1, "model": "point"},
                 "eps_r": 6.1, "sigma_eps_r": 0.3}
    t0, t1 = out["targets"]
    assert (t0["depth_m"], t0["sigma_depth_m"]) == (0.21, 0.01)
    assert math.isnan(t1["depth_m"]) and math.isnan(t1["sigma_depth_m"])  # its fit failed
    assert t0["fit"] == {"ok": True, "eps_r": 6.1, "depth_m": 0.21, "sigma_depth_m": 0.01, "apex_time_s": 2e-9,
                         "rms_s": 1e-11, "n_picks": 12}
    # a target without an apex: the box's middle trace, and no apexes handed to the fit
    bare = [{"box": [4, 1e-9, 8, 3e-9]}, TARGETS[1]]
    out = estimate_depths(_record(), bare, method="fit", trace_spacing_m=0.02)
    assert stubs["apexes"] is None and out["targets"][0]["x_m"] == pytest.approx(0.12)


@pytest.mark.parametrize("net_eps, agrees", [(7.0, True), (9.0, False)])
def test_the_hybrid_refines_the_network_with_the_bias_corrected_fit_only_where_they_agree(stubs, net_eps, agrees):
    net = _Net(net_eps, 0.5, [0.2, 0.35])
    out = estimate_depths(_record(), TARGETS, estimator=net, trace_spacing_m=0.02)  # hybrid by default
    p = out["permittivity"]
    fc = 6.1 / (1 + FIT_BIAS)  # 7.044
    assert p["fit_agrees"] is agrees and p["method"] == "hybrid"
    if agrees:  # |6.995 - 7.0| <= 2 x 0.5: inverse-variance mean with the fit's widened sigma
        sf = math.hypot(0.3 / (1 + FIT_BIAS), FIT_MODEL_ERROR * fc)
        w1, w2 = 1 / 0.5**2, 1 / sf**2
        eps, sig = (w1 * 7.0 + w2 * fc) / (w1 + w2), 1 / math.sqrt(w1 + w2)
    else:  # 9.0 is more than two sigmas from 6.995: the network's alone
        eps, sig = 9.0, 0.5
    assert p["eps_r"] == pytest.approx(eps, rel=1e-12) and p["sigma_eps_r"] == pytest.approx(sig, rel=1e-12)
    d0 = 0.2 * math.sqrt(net_eps / eps)  # the network's depth, rescaled to the refined speed
    assert out["targets"][0]["depth_m"] == pytest.approx(d0, rel=1e-12)
    assert out["targets"][0]["sigma_depth_m"] == pytest.approx(d0 * 0.5 * sig / eps, rel=1e-12)


def test_an_unknown_method_is_named():
    with pytest.raises(InvalidDataError, match=re.escape("unknown depth method 'both'; choose one of hybrid, net, "
                                                         "fit")):
        estimate_depths(_record(), TARGETS, method="both")


@pytest.mark.parametrize("radius, radii", [(0.008, [0.008, 0.008]), ([0.006, 0.012], [0.006, 0.012])])
def test_known_radii_go_to_a_cylinder_fit_and_the_hybrid_takes_its_own_bias_and_error(stubs, radius, radii):
    net = _Net(6.4, 0.5, [0.2, 0.35])
    out = estimate_depths(_record(), TARGETS, estimator=net, trace_spacing_m=0.02, radius_m=radius)
    assert stubs["model"] == "point" and stubs["radius_m"] == radii and stubs["spacing"] == 0.02
    assert stubs["boxes"] == [[5.0, 1e-9, 15.0, 3e-9], [20.0, 1e-9, 33.0, 3e-9]]
    assert stubs["apexes"] == [(10.0, 2e-9), (25.5, 2.2e-9)]
    p = out["permittivity"]
    assert p["fit"]["model"] == "cylinder, radius given" and p["fit_agrees"] is True
    fc = 6.1 / (1 + FIT_BIAS_RADIUS)  # 6.237: within 2 x 0.5 of 6.4
    sf = math.hypot(0.3 / (1 + FIT_BIAS_RADIUS), FIT_MODEL_ERROR_RADIUS * fc)
    w1, w2 = 1 / 0.5**2, 1 / sf**2
    assert p["eps_r"] == pytest.approx((w1 * 6.4 + w2 * fc) / (w1 + w2), rel=1e-12)
    assert p["sigma_eps_r"] == pytest.approx(1 / math.sqrt(w1 + w2), rel=1e-12)


def test_a_wrong_radius_is_named_before_any_work(stubs):
    net = _Net(6.4, 0.5, [0.2, 0.35])
    with pytest.raises(InvalidDataError, match="radius_m has 3 values for 2 boxes: give one, or one per box"):
        estimate_depths(_record(), TARGETS, estimator=net, trace_spacing_m=0.02, radius_m=[0.01, 0.01, 0.01])
    with pytest.raises(InvalidDataError, match="radius_m must be a number of metres in 0..50, got -0.01"):
        estimate_depths(_record(), TARGETS, estimator=net, trace_spacing_m=0.02, radius_m=-0.01)
    assert net.calls == [] and "model" not in stubs


def test_an_apex_needs_both_its_trace_and_time_or_none_reach_the_fit(stubs):
    half = [dict(TARGETS[0]), {"box": TARGETS[1]["box"], "apex_trace": 25.5, "apex_time_s": None}]
    estimate_depths(_record(), half, method="fit", trace_spacing_m=0.02)
    assert stubs["apexes"] is None
    half[1] = {"box": TARGETS[1]["box"], "apex_trace": None, "apex_time_s": 2.2e-9}
    estimate_depths(_record(), half, method="fit", trace_spacing_m=0.02)
    assert stubs["apexes"] is None


def test_the_shipped_network_is_loaded_when_none_is_given(stubs, monkeypatch):
    from gpr3d.inversion import depthnet

    net = _Net(7.0, 0.7, [0.2, 0.35])
    monkeypatch.setattr(depthnet.DepthEstimator, "load", classmethod(lambda cls, *a, **k: net))
    out = estimate_depths(_record(), TARGETS, method="net", trace_spacing_m=0.02)
    assert len(net.calls) == 1 and out["permittivity"]["eps_r"] == 7.0


@pytest.mark.parametrize("method", ["fit", "hybrid"])
def test_no_targets_give_no_fit_and_the_hybrid_keeps_the_network(stubs, method):
    net = _Net(7.0, 0.7, [])
    out = estimate_depths(_record(), [], method=method, estimator=net, trace_spacing_m=0.02)
    p = out["permittivity"]
    assert "fit" not in p and "model" not in stubs and out["targets"] == []
    if method == "fit":
        assert math.isnan(p["eps_r"]) and math.isnan(p["sigma_eps_r"])
    else:
        assert (p["eps_r"], p["sigma_eps_r"], p["fit_agrees"]) == (7.0, 0.7, False)


@pytest.mark.parametrize("net_eps, agrees", [(7.0, True), (5.0, True), (7.25, False), (4.75, False)])
def test_the_fit_agrees_up_to_two_network_sigmas_inclusive(stubs, monkeypatch, net_eps, agrees):
    import gpr3d.inversion.estimate as estimate

    monkeypatch.setattr(estimate, "FIT_BIAS", 0.0)
    stubs["fit_eps"] = 6.0  # |6 - 7| is exactly 2 x 0.5; 7.25 is 2.5 sigmas off
    out = estimate_depths(_record(), TARGETS, estimator=_Net(net_eps, 0.5, [0.2, 0.35]), trace_spacing_m=0.02)
    assert out["permittivity"]["fit_agrees"] is agrees
