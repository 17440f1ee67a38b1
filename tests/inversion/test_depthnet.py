"""DepthNet: windows drawn to a physical scale, labels in them, training that learns, weights that round-trip."""

import math

import numpy as np
import pytest

from gpr3d.core.errors import FormatError, InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.core.units import C0
from gpr3d.inversion.depthnet import (DepthConfig, box_to_window, depth_window, prepare_depth_record,
                                      window_targets_m)


def hyperbola_record(*, spacing, eps=9.0, depth=0.3, x0=1.0, length=2.0, f=8e8, dt=2.5e-11, ns=800, h=0.0,
                     t_dw=2e-9):
    """A record of one point diffractor (Ricker pulses along its exact travel times) and a direct wave."""
    x = np.arange(0.0, length + 1e-9, spacing)
    t = np.arange(ns) * dt
    v = C0 / math.sqrt(eps)
    arr = t_dw + 2 * np.hypot(x - x0, depth) / v

    def ricker(tc, amp):
        a = (np.pi * f * (t[None, :] - tc[:, None])) ** 2
        return amp[:, None] * (1 - 2 * a) * np.exp(-a)

    data = ricker(arr, (depth / np.hypot(x - x0, depth)) ** 2) + 3 * ricker(np.full(x.size, t_dw), np.ones(x.size))
    pos = np.stack([x, 0 * x, 0 * x], axis=1)
    s = Survey(data=data.astype(np.float32), dt_s=dt, positions_xyz=pos, offset_m=h, frequency_hz=f)
    apex_trace = float(np.interp(x0, x, np.arange(x.size)))
    lab = {"kind": "rebar", "apex_trace": apex_trace, "apex_time_s": float(arr.min()), "depth_m": depth,
           "box": [apex_trace - 0.3 / spacing, float(arr.min() - 1 / f), apex_trace + 0.3 / spacing,
                   float(arr.min() + 3 / f)], "visible": True}
    return s, {"eps_r": eps, "labels": [lab]}


def test_windows_do_not_depend_on_the_trace_spacing():
    """The picture is drawn in metres: 5 mm and 2 cm trace spacing give the same window (the hyperbola's shape)."""
    cfg = DepthConfig(size=128)
    ims = []
    for spacing in (0.005, 0.02):
        s, lab = hyperbola_record(spacing=spacing)
        rec = prepare_depth_record(s, lab, size=128)
        im, left, width = depth_window(rec, 1.0, cfg)
        assert width == pytest.approx(cfg.alpha * C0 * (s.n_samples - 1) * s.dt_s / 2)
        assert left == pytest.approx(1.0 - width / 2)
        ims.append(im[1])  # the envelope channel
    a, b = ims
    rows = slice(30, 128)  # below the direct wave
    corr = np.corrcoef(a[rows].ravel(), b[rows].ravel())[0, 1]
    assert corr > 0.97
    # the apex (8 ns of 20: row 51) lies in the middle column; a window that ignored positions (one
    # column per trace) would put it elsewhere at 5 mm
    apex_rows = slice(46, 57)
    for im in (a, b):
        w = im[apex_rows].max(axis=0) ** 4
        centre = float(np.sum(w * (np.arange(128) + 0.5)) / np.sum(w))  # x = 1.0 m is the window's middle
        assert centre == pytest.approx(64.0, abs=1.5)


def test_hyperbola_asymptote_slope_is_alpha_sqrt_eps_in_the_picture():
    """Where the window puts the hyperbola: its arrivals follow alpha * sqrt(eps) per column far from the apex."""
    cfg = DepthConfig(size=224, alpha=0.5)
    s, lab = hyperbola_record(spacing=0.01, eps=9.0, depth=0.05, length=4.0, x0=2.0, ns=1200)
    rec = prepare_depth_record(s, lab, size=224)
    im, left, width = depth_window(rec, 2.0, cfg)
    env = im[1]
    cols = np.arange(150, 200)
    rows = np.array([np.argmax(env[40:, c]) + 40 for c in cols], float)
    slope = np.polyfit(cols, rows, 1)[0]
    assert slope == pytest.approx(cfg.alpha * math.sqrt(9.0), rel=0.08)


def test_labels_map_into_the_window_with_depth_as_a_fraction_of_the_window_depth():
    s, lab = hyperbola_record(spacing=0.01)
    rec = prepare_depth_record(s, lab, size=224)
    cfg = DepthConfig()
    _, left, width = depth_window(rec, 1.1, cfg)
    boxes, q = window_targets_m(rec, left, width, 224)
    assert q.tolist() == pytest.approx([0.3 / (C0 * rec.window_s / 2)])
    b = box_to_window(rec, lab["labels"][0]["box"], left, width, 224)
    # the box is centred on the apex at x = 1.0, 0.1 m left of the window's centre
    assert 0.5 * (b[0] + b[2]) == pytest.approx(112 - 0.1 / width * 224, abs=1e-3)
    assert b[1] == pytest.approx(lab["labels"][0]["box"][1] / rec.s_per_row + 0.5)
    assert boxes[0].tolist() == pytest.approx([max(b[0], 0), b[1], min(b[2], 224), b[3]])
    # a window far away holds no target
    _, left2, width2 = depth_window(rec, 1.0 + 2 * width, cfg)
    assert window_targets_m(rec, left2, width2, 224)[0].shape == (0, 4)


def test_records_without_positions_need_a_spacing():
    s, lab = hyperbola_record(spacing=0.01)
    bare = s.replace(positions_xyz=None)
    with pytest.raises(InvalidDataError, match="trace spacing"):
        prepare_depth_record(bare, lab)
    rec = prepare_depth_record(bare, lab, trace_spacing_m=0.01)
    assert rec.x_m[-1] == pytest.approx(0.01 * (s.n_traces - 1), abs=1e-6)


def test_config_is_checked():
    for kw in ({"arch": "vgg"}, {"width": 3}, {"size": 100}, {"alpha": 0}):
        with pytest.raises(InvalidDataError):
            DepthConfig(**kw)


torch = pytest.importorskip("torch")


def test_training_learns_permittivity_and_depth_and_weights_round_trip(tmp_path):
    """A small DepthNet trained briefly tells a slow host from a fast one, and depths apart; fp16 file reloads."""
    from gpr3d.inversion.depthnet import (DepthEstimator, DepthTrainConfig, load_depthnet, save_depthnet,
                                          train_depthnet)

    rng = np.random.default_rng(0)
    recs = []
    for k in range(16):
        eps = 4.0 if k % 2 else 16.0
        depth = float(rng.uniform(0.15, 0.5))
        s, lab = hyperbola_record(spacing=0.02, eps=eps, depth=depth, x0=float(rng.uniform(0.6, 1.4)), ns=600)
        recs.append(prepare_depth_record(s, lab, size=64))
    net = {"arch": "resnet10n", "width": 8, "size": 64, "alpha": 0.5}
    cfg = DepthTrainConfig(out=str(tmp_path / "run"), steps=120, batch=8, seed=0, net=net, checkpoint_every=60)
    res = train_depthnet(cfg, recs, progress=False, log=lambda *a: None)
    assert res["steps"] == 120 and (tmp_path / "run" / "checkpoint.pt").exists()
    est = DepthEstimator(res["model"], DepthConfig(**net))
    slow = [est.predict(r, [1.0], [[]])[0][0] for r in recs[0::2]]
    fast = [est.predict(r, [1.0], [[]])[0][0] for r in recs[1::2]]
    assert np.median(slow) > 1.5 * np.median(fast)
    # depths: the deeper half of the targets comes out deeper
    d_true, d_est = [], []
    for r, k in zip(recs, range(16)):
        box = r.labels[0]["box"]
        d_est.append(est.predict(r, [r.x_of_trace(r.labels[0]["apex_trace"])], [[box]])[1][0][0])
        d_true.append(r.labels[0]["depth_m"])
    assert np.corrcoef(d_true, d_est)[0, 1] > 0.8
    # fp16 weights reload to the same outputs (within half precision)
    path = tmp_path / "dn.pt"
    save_depthnet(res["model"], DepthConfig(**net), path, provenance={"validation": {"eps_rel_rmse": 0.2}})
    model2, net2, prov = load_depthnet(path)
    est2 = DepthEstimator(model2, net2, prov)
    e1 = est.predict(recs[0], [1.0], [[]])[0][0]
    e2 = est2.predict(recs[0], [1.0], [[]])[0][0]
    assert e2 == pytest.approx(e1, rel=0.02)
    # the ONNX export (what ships) gives the same numbers without PyTorch
    pytest.importorskip("onnx")
    from gpr3d.inversion.depthnet import export_depthnet_onnx

    info = export_depthnet_onnx(path, tmp_path / "dn.onnx")
    # this 120-step net's outputs (eps_r relative, depths in window fractions): under 1e-3 on the AMD hosts of earlier
    # sessions and in one run on an Intel Xeon (rocketlake to LLVM), 1.17e-3 in another run there (CI, 2026-12-05):
    # the net trained here differs from run to run and host to host, and so does how far ONNX Runtime's float32 sums
    # land from PyTorch's; the shipped weights export to 1e-4. 3e-3 leaves that spread room. The export's inputs,
    # names and answers are held to 1e-3 on a fixed net by test_depthnet_by_hand.py's ONNX test.
    assert info["max_diff"] < 3e-3
    est3 = DepthEstimator.load(tmp_path / "dn.onnx")
    r = recs[2]
    boxes = [[r.labels[0]["box"]], [], [r.labels[0]["box"]] * 3]
    centres = [1.0, 0.8, 1.2]
    e2, q2 = est2.predict(r, centres, boxes)
    e3, q3 = est3.predict(r, centres, boxes)
    np.testing.assert_allclose(e3, e2, rtol=1e-3)
    assert [len(q) for q in q3] == [1, 0, 3]
    np.testing.assert_allclose(np.concatenate(q3), np.concatenate(q2), rtol=1e-3, atol=1e-5)
    # training can start from saved weights (a different net is refused)
    cont = DepthTrainConfig(out=str(tmp_path / "cont"), steps=2, batch=8, lr=1e-9, net=net, init=str(path))
    res3 = train_depthnet(cont, recs, progress=False, log=lambda *a: None)
    start = dict(model2.named_parameters())
    for name, p in res3["model"].named_parameters():  # lr 1e-9: the parameters are still the saved ones
        np.testing.assert_allclose(p.detach().numpy(), start[name].detach().numpy(), atol=1e-6, err_msg=name)
    from gpr3d.core.errors import GPR3DError

    with pytest.raises(GPR3DError, match="width 8, not resnet10n width 16"):
        train_depthnet(DepthTrainConfig(out=str(tmp_path / "c2"), steps=2, batch=8, init=str(path),
                                        net=dict(net, width=16)), recs, progress=False, log=lambda *a: None)
    out = est2.estimate(None, [], record=recs[0])
    assert out["sigma_eps_r"] >= 0.2 * out["eps_r"] - 1e-9 and out["depth_m"] == []
    # running the same training again resumes at its end instead of starting over
    res2 = train_depthnet(cfg, recs, progress=False, log=lambda *a: None)
    assert res2["steps"] == 120 and res2["wall_s"] < res["wall_s"]


def test_bad_weight_files_get_one_line(tmp_path):
    from gpr3d.inversion.depthnet import load_depthnet

    with pytest.raises(FormatError, match="no such"):
        load_depthnet(tmp_path / "missing.pt")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(FormatError, match="not a readable"):
        load_depthnet(junk)
    torch.save({"format": "gpr3d.detector"}, tmp_path / "det.pt")
    with pytest.raises(FormatError, match="not a gpr3d DepthNet"):
        load_depthnet(tmp_path / "det.pt")
    pytest.importorskip("onnxruntime")
    from gpr3d.detection.ort import NMS_ONNX
    from gpr3d.inversion.depthnet import DepthEstimator

    with pytest.raises(FormatError, match="without gpr3d DepthNet metadata"):
        DepthEstimator.load(NMS_ONNX)  # an ONNX graph, but not ours
    (tmp_path / "junk.onnx").write_bytes(b"junk")
    with pytest.raises(FormatError, match="not a readable ONNX DepthNet"):
        DepthEstimator.load(tmp_path / "junk.onnx")


def test_a_time_crop_shows_the_same_times_and_keeps_the_targets_inside():
    from gpr3d.inversion.depthnet import crop_time

    s, lab = hyperbola_record(spacing=0.01, depth=0.3)
    late = dict(lab["labels"][0], apex_time_s=15e-9, depth_m=0.6)
    rec = prepare_depth_record(s, {"eps_r": 9.0, "labels": [lab["labels"][0], late]}, size=224)
    c = crop_time(rec, 0.5)
    assert c.window_s == pytest.approx(rec.window_s * 112 / 223, rel=1e-9, abs=0)
    # the same direct-wave time
    assert c.direct_frac * c.window_s == pytest.approx(rec.direct_frac * rec.window_s, rel=1e-9, abs=0)
    assert [x["depth_m"] for x in c.labels] == [0.3]  # the apex at 15 ns lies past the cut (10 ns)
    # row k of the crop shows the time k * c.s_per_row of the original
    k = np.arange(224)
    src = k * c.s_per_row / rec.s_per_row
    expect = np.array([np.interp(src, np.arange(224), row) for row in rec.proc[::20]])
    np.testing.assert_allclose(c.proc[::20], expect, atol=1e-5)
    # and the window in metres shrinks with the time window
    assert c.depth_scale_m == pytest.approx(rec.depth_scale_m * c.window_s / rec.window_s)
