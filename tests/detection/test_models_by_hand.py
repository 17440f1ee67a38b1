"""Every detector as the module's docstring describes it, read back from the built torchvision model: backbone cut and
channels, FPN, anchors, proposal and sampling counts, thresholds, heads, input transform, trainable batch norm."""

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from gpr3d.core.errors import InvalidDataError  # noqa: E402
from gpr3d.detection.models import build_model, count_parameters  # noqa: E402

RATIOS = (0.25, 0.5, 1.0, 2.0)  # anchor heights over widths: wide and flat to square
TWO_SCALES = ((16, 24), (32, 48), (64, 96), (128, 192), (256, 384))


class _Build:
    """Each test builds the models it reads, in its own body (so that a mutation test run maps every model's
    construction to the tests that check it)."""

    def __getitem__(self, name):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return build_model(name)


@pytest.fixture
def built():
    return _Build()


def _inner_channels(model):
    return [b[0].in_channels for b in model.backbone.fpn.inner_blocks]


def _transform_is_the_window(model, size=256):
    t = model.transform
    assert t.min_size == (size,) and t.max_size == size
    assert t.image_mean == [0.5, 0.5, 0.5] and t.image_std == [0.25, 0.25, 0.25]


def _frcnn_counts(model):
    assert model.rpn._pre_nms_top_n == {"training": 1000, "testing": 500}
    assert model.rpn._post_nms_top_n == {"training": 300, "testing": 150}
    rh = model.roi_heads
    assert (rh.fg_bg_sampler.batch_size_per_image, rh.detections_per_img, rh.score_thresh) == (128, 100, 0.01)
    assert rh.box_predictor.cls_score.out_features == 2 and rh.box_predictor.bbox_pred.out_features == 8


def _batch_norm_trains(model):
    kinds = {type(m).__name__ for m in model.modules()}
    assert "FrozenBatchNorm2d" not in kinds and "BatchNorm2d" in kinds
    assert all(p.requires_grad for p in model.parameters())


def test_the_lean_faster_rcnn(built):
    m = built["frcnn_lean"]
    body = m.backbone.body
    # ResNet-18 cut after its third stage: layers 1-3 feed a 128-channel FPN (and its max-pool level)
    assert body.return_layers == {"layer1": "0", "layer2": "1", "layer3": "2"} and not hasattr(body, "layer4")
    assert _inner_channels(m) == [64, 128, 256] and m.backbone.out_channels == 128
    assert type(m.backbone.fpn.extra_blocks).__name__ == "LastLevelMaxPool"
    assert m.rpn.anchor_generator.sizes == TWO_SCALES[:4]
    assert m.rpn.anchor_generator.aspect_ratios == (RATIOS,) * 4
    pool = m.roi_heads.box_roi_pool
    assert (pool.featmap_names, pool.output_size, pool.sampling_ratio) == (["0", "1", "2"], (7, 7), 2)
    head = m.roi_heads.box_head
    assert (head.fc6.in_features, head.fc6.out_features, head.fc7.out_features) == (128 * 7 * 7, 512, 512)
    assert m.roi_heads.box_predictor.cls_score.in_features == 512
    _frcnn_counts(m)
    _transform_is_the_window(m)
    _batch_norm_trains(m)
    assert 6e6 < count_parameters(m) < 8e6  # "about 7 M"


@pytest.mark.parametrize("name, channels, layer3", [("frcnn_r18", [64, 128, 256, 512], 2),
                                                     ("frcnn_r50", [256, 512, 1024, 2048], 6),
                                                     ("frcnn_r101", [256, 512, 1024, 2048], 23)])
def test_the_resnet_faster_rcnns(built, name, channels, layer3):
    m = built[name]
    assert m.backbone.body.return_layers == {"layer1": "0", "layer2": "1", "layer3": "2", "layer4": "3"}
    assert len(m.backbone.body.layer3) == layer3  # which ResNet
    assert _inner_channels(m) == channels and m.backbone.out_channels == 256
    assert m.rpn.anchor_generator.sizes == TWO_SCALES
    assert m.rpn.anchor_generator.aspect_ratios == (RATIOS,) * 5
    assert m.roi_heads.box_predictor.cls_score.in_features == 1024  # torchvision's two-layer head
    _frcnn_counts(m)
    _transform_is_the_window(m)
    _batch_norm_trains(m)


def test_the_mobilenet_faster_rcnn(built):
    m = built["frcnn_mobilenet"]
    _frcnn_counts(m)
    _transform_is_the_window(m)
    _batch_norm_trains(m)  # every backbone layer trainable


def test_the_one_stage_detectors(built):
    r = built["retinanet_r18"]
    assert r.backbone.body.return_layers == {"layer2": "0", "layer3": "1", "layer4": "2"}
    assert _inner_channels(r) == [128, 256, 512] and r.backbone.out_channels == 256
    p6 = r.backbone.fpn.extra_blocks.p6
    assert (p6.in_channels, p6.out_channels) == (256, 256)
    assert r.anchor_generator.sizes == TWO_SCALES and r.anchor_generator.aspect_ratios == (RATIOS,) * 5
    f = built["fcos_r18"]
    assert _inner_channels(f) == [128, 256, 512]
    assert f.anchor_generator.sizes == ((8,), (16,), (32,), (64,), (128,))
    assert f.anchor_generator.aspect_ratios == ((1.0,),) * 5
    for m in (r, f):
        assert m.head.classification_head.num_classes == 2
        assert (m.score_thresh, m.detections_per_img) == (0.01, 100)
        _transform_is_the_window(m)
        _batch_norm_trains(m)


def test_fcos_box_distances_stay_positive_and_keep_their_gradient(built):
    # torchvision's FCOS puts its box distances through a ReLU; once every output is negative the boxes are empty,
    # the GIoU loss is 1 everywhere and no gradient reaches the head again. Ours is a softplus.
    head = built["fcos_r18"].head.regression_head
    conv = head.bbox_reg
    x = torch.randn(1, 256, 4, 4, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        conv.bias.copy_(torch.linspace(-2.0, 2.0, conv.bias.numel()))  # outputs on both sides of 0
        pre = torch.nn.functional.conv2d(x, conv.weight, conv.bias, padding=1)
        # float32 softplus against its formula: a few ulps on any host, well inside assert_close's 1.3e-6 relative
        torch.testing.assert_close(conv(x), torch.log1p(torch.exp(pre)))
        conv.bias.fill_(-30.0)  # a head pushed far below zero, as a diverging step leaves it
    out = conv(x)
    assert (out > 0).all()
    out.sum().backward()
    assert conv.bias.grad.min() > 0  # a ReLU gives exactly 0 here
    reg, _ = head([torch.randn(1, 256, 4, 4)])
    assert reg.shape == (1, 16, 4) and (reg > 0).all()


def test_ssdlite(built):
    m = built["ssdlite"]
    _transform_is_the_window(m)
    assert m.transform.fixed_size == (256, 256)
    assert (m.score_thresh, m.detections_per_img) == (0.01, 100)
    bns = [b for b in m.modules() if isinstance(b, torch.nn.BatchNorm2d)]
    assert bns and all((b.eps, b.momentum) == (0.001, 0.03) for b in bns)
    last = m.head.classification_head.module_list[-1][-1]
    assert last.out_channels == 6 * 2  # six anchors per cell, two classes
    _batch_norm_trains(m)


def test_another_window_size_and_the_same_start_every_time():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = build_model("frcnn_lean", image_size=320)
        torch.manual_seed(123)
        b = build_model("frcnn_lean", image_size=320)
        s = build_model("ssdlite", image_size=320)
    _transform_is_the_window(a, 320)
    assert s.transform.fixed_size == (320, 320) and s.transform.max_size == 320 and s.transform.min_size == (320,)
    sa, sb = a.state_dict(), b.state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa)  # seeded inside: whatever the caller's generator did


def test_an_unknown_name_is_named():
    with pytest.raises(InvalidDataError) as err:
        build_model("yolo")
    assert str(err.value) == ("unknown detector 'yolo'; choose one of frcnn_lean, frcnn_r18, frcnn_r50, frcnn_r101, "
                              "frcnn_mobilenet, retinanet_r18, fcos_r18, ssdlite")
    m = build_model()  # the lean one by default
    assert m.backbone.out_channels == 128 and not hasattr(m.backbone.body, "layer4")
