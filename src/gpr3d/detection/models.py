"""Hyperbola detectors from torchvision, built without downloaded weights.

Every model takes the 3-channel 256 x 256 windows of :mod:`gpr3d.detection.windows`
and finds hyperbolas: one class, ``hyperbola`` (label 1), or with ``kinds`` one class per
target kind (label ``k + 1`` for ``kinds[k]``). A Faster R-CNN with kinds scores each box
by how likely it is a target of any kind (one minus the background probability) and
names its most likely kind with that kind's share (``kind_scores``), so a hyperbola whose
kind is in doubt is still found (:class:`gpr3d.detection.kindheads.KindRoIHeads`). Names (``MODELS``):

* ``frcnn_lean`` (the default): Faster R-CNN on a ResNet-18 cut after its third
  stage, a 128-channel FPN, anchors shaped for hyperbola boxes (wide and flat to
  square), 1000/300 proposals and 128 sampled RoIs in training. About 7 M
  parameters: trains on CPU, runs a window in a few tens of milliseconds.
* ``frcnn_r18``, ``frcnn_r50``, ``frcnn_r101``: Faster R-CNN with full ResNet FPN
  backbones (the reference's best model is ResNet-101).
* ``frcnn_mobilenet``: Faster R-CNN MobileNetV3-Large FPN.
* ``retinanet_r18``, ``fcos_r18``: one-stage detectors on a ResNet-18 FPN. FCOS's box
  distances pass through a softplus rather than torchvision's ReLU: trained from scratch,
  a ReLU head whose outputs all go negative predicts empty boxes, its GIoU loss sits at
  1 with no gradient, and it never recovers (seen on a device-held-out split).
* ``ssdlite``: SSDlite with MobileNetV3-Large (as the reference's SSD rows).

Batch norm is trainable throughout (nothing is pretrained).
"""

from __future__ import annotations

from functools import lru_cache, partial

from gpr3d.core.deps import require, resolve_device  # noqa: F401 - resolve_device kept here for callers
from gpr3d.core.errors import InvalidDataError

__all__ = ["MODELS", "build_model", "count_parameters", "resolve_device", "widen_to_kinds"]

MODELS = ("frcnn_lean", "frcnn_r18", "frcnn_r50", "frcnn_r101", "frcnn_mobilenet", "retinanet_r18", "fcos_r18",
          "ssdlite")

#: anchor heights over widths: hyperbola boxes are wide and flat to about square
ASPECT_RATIOS = (0.25, 0.5, 1.0, 2.0)
IMAGE_MEAN = [0.5, 0.5, 0.5]
IMAGE_STD = [0.25, 0.25, 0.25]


def _anchors(n_levels: int, base: int = 16):
    """Two sizes per level (``base 2^k`` and 1.5 times that), each in every aspect ratio."""
    from torchvision.models.detection.anchor_utils import AnchorGenerator

    sizes = tuple((base * 2**k, int(base * 2**k * 1.5)) for k in range(n_levels))
    return AnchorGenerator(sizes=sizes, aspect_ratios=(ASPECT_RATIOS,) * n_levels)


def _resnet_fpn(name: str, *, returned=(1, 2, 3, 4), out_channels: int = 256, extra=None):
    import torch.nn as nn
    import torchvision
    from torchvision.models.detection.backbone_utils import BackboneWithFPN
    body = getattr(torchvision.models, name)(weights=None, norm_layer=nn.BatchNorm2d)
    in_ch = body.inplanes // 8  # channels of layer1's output (64 for resnet18, 256 for resnet50)
    return_layers = {f"layer{k}": str(i) for i, k in enumerate(returned)}
    in_list = [in_ch * 2 ** (k - 1) for k in returned]
    # extra None: torchvision's max-pool level on top
    return BackboneWithFPN(body, return_layers, in_list, out_channels, extra_blocks=extra, norm_layer=None)


def _frcnn_common(image_size: int) -> dict:
    return dict(min_size=image_size, max_size=image_size, image_mean=IMAGE_MEAN, image_std=IMAGE_STD,
                rpn_pre_nms_top_n_train=1000, rpn_post_nms_top_n_train=300, rpn_pre_nms_top_n_test=500,
                rpn_post_nms_top_n_test=150, box_batch_size_per_image=128, box_detections_per_img=100,
                box_score_thresh=0.01)


def build_model(name: str = "frcnn_lean", *, image_size: int = 256, kinds=None):
    """A fresh detector ``name`` (see ``MODELS``) for ``image_size`` square windows.

    ``kinds``: the target kinds it tells apart (``None``: one class, ``hyperbola``).
    """
    torch = require("torch")
    require("torchvision")
    import torchvision.models.detection as det
    from torchvision.models.detection.faster_rcnn import FastRCNNPredictor, TwoMLPHead
    from torchvision.ops import MultiScaleRoIAlign

    if name not in MODELS:
        raise InvalidDataError(f"unknown detector {name!r}; choose one of {', '.join(MODELS)}")
    n_cls = 2 if not kinds else len(kinds) + 1
    torch.manual_seed(0)
    common = _frcnn_common(image_size)
    if name == "frcnn_lean":
        bb = _resnet_fpn("resnet18", returned=(1, 2, 3), out_channels=128)
        pool = MultiScaleRoIAlign(featmap_names=["0", "1", "2"], output_size=7, sampling_ratio=2)
        model = det.FasterRCNN(bb, num_classes=None, rpn_anchor_generator=_anchors(4), box_roi_pool=pool,
                               box_head=TwoMLPHead(128 * 7 * 7, 512), box_predictor=FastRCNNPredictor(512, n_cls),
                               **common)
    elif name in ("frcnn_r18", "frcnn_r50", "frcnn_r101"):
        bb = _resnet_fpn({"frcnn_r18": "resnet18", "frcnn_r50": "resnet50", "frcnn_r101": "resnet101"}[name])
        model = det.FasterRCNN(bb, num_classes=n_cls, rpn_anchor_generator=_anchors(5), **common)
    elif name == "frcnn_mobilenet":
        model = det.fasterrcnn_mobilenet_v3_large_fpn(weights=None, weights_backbone=None, num_classes=n_cls,
                                                      trainable_backbone_layers=6, **common)
    elif name in ("retinanet_r18", "fcos_r18"):
        from torchvision.ops.feature_pyramid_network import LastLevelP6P7

        bb = _resnet_fpn("resnet18", returned=(2, 3, 4), extra=LastLevelP6P7(256, 256))
        kw = dict(min_size=image_size, max_size=image_size, image_mean=IMAGE_MEAN, image_std=IMAGE_STD,
                  score_thresh=0.01, detections_per_img=100)
        if name == "retinanet_r18":
            model = det.RetinaNet(bb, num_classes=n_cls, anchor_generator=_anchors(5, base=16), **kw)
        else:
            from torchvision.models.detection.anchor_utils import AnchorGenerator

            anchors = AnchorGenerator(sizes=tuple((8 * 2**k,) for k in range(5)), aspect_ratios=((1.0,),) * 5)
            model = det.FCOS(bb, num_classes=n_cls, anchor_generator=anchors, **kw)
            model.head.regression_head.bbox_reg.__class__ = _softplus_conv()
    else:  # ssdlite
        from torchvision.models.detection import ssdlite

        model = det.ssdlite320_mobilenet_v3_large(weights=None, weights_backbone=None, num_classes=n_cls,
                                                  norm_layer=partial(torch.nn.BatchNorm2d, eps=0.001, momentum=0.03),
                                                  image_mean=IMAGE_MEAN, image_std=IMAGE_STD, score_thresh=0.01,
                                                  detections_per_img=100)
        model.transform.min_size = (image_size,)
        model.transform.max_size = image_size
        model.transform.fixed_size = (image_size, image_size)
        _ = ssdlite
    if kinds and isinstance(model, det.FasterRCNN):
        from gpr3d.detection.kindheads import KindRoIHeads

        model.roi_heads.__class__ = KindRoIHeads  # the same parts; only inference differs
    return model


@lru_cache(maxsize=None)  # one class, made on first use: importing this module needs no torch
def _softplus_conv():
    import torch

    class SoftplusConv2d(torch.nn.Conv2d):
        """A convolution whose outputs pass through a softplus: positive, and never without gradient."""

        def forward(self, x):
            return torch.nn.functional.softplus(super().forward(x))

    return SoftplusConv2d


def widen_to_kinds(state_dict: dict, kinds, from_kinds=None) -> dict:
    """A Faster R-CNN state dict made into one that names ``kinds``.

    From a one-class model (``from_kinds`` None): each kind starts as a copy of
    ``hyperbola`` (its class row and box regression), its logit lowered by
    ``log(len(kinds))``, so that ``1 - p(background)`` and every box are those of the
    one-class model; training then tells the kinds apart. From a model of
    ``from_kinds``: each kind keeps its own rows (``kinds`` must be among them).
    """
    import math

    torch = require("torch")
    out = dict(state_dict)
    k = len(kinds)
    w, b = state_dict["roi_heads.box_predictor.cls_score.weight"], state_dict["roi_heads.box_predictor.cls_score.bias"]
    bw, bb = state_dict["roi_heads.box_predictor.bbox_pred.weight"], state_dict["roi_heads.box_predictor.bbox_pred.bias"]
    if from_kinds:
        missing = [x for x in kinds if x not in from_kinds]
        if missing or w.shape[0] != len(from_kinds) + 1:
            raise InvalidDataError(f"the detector names {', '.join(from_kinds)}: it cannot start "
                                   f"{', '.join(missing) or 'these kinds'}")
        rows = [0] + [list(from_kinds).index(x) + 1 for x in kinds]
        box_rows = [4 * r + i for r in rows for i in range(4)]
        out["roi_heads.box_predictor.cls_score.weight"], out["roi_heads.box_predictor.cls_score.bias"] = w[rows], b[rows]
        out["roi_heads.box_predictor.bbox_pred.weight"] = bw[box_rows]
        out["roi_heads.box_predictor.bbox_pred.bias"] = bb[box_rows]
        return out
    if w.shape[0] != 2:
        raise InvalidDataError(f"only a one-class detector can be widened to kinds (this one has {w.shape[0] - 1})")
    out["roi_heads.box_predictor.cls_score.weight"] = torch.cat([w[:1]] + [w[1:2]] * k)
    out["roi_heads.box_predictor.cls_score.bias"] = torch.cat([b[:1]] + [b[1:2] - math.log(k)] * k)
    out["roi_heads.box_predictor.bbox_pred.weight"] = torch.cat([bw[:4]] + [bw[4:8]] * k)
    out["roi_heads.box_predictor.bbox_pred.bias"] = torch.cat([bb[:4]] + [bb[4:8]] * k)
    return out


def count_parameters(model) -> int:
    return int(sum(p.numel() for p in model.parameters()))
