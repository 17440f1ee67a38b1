"""Faster R-CNN's box head for a detector of target kinds (imports torch and torchvision).

:func:`gpr3d.detection.models.build_model` gives a Faster R-CNN built with ``kinds`` this
head; :mod:`gpr3d.detection.models` itself imports without torchvision.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torchvision.models.detection.roi_heads import RoIHeads
from torchvision.ops import boxes as box_ops

__all__ = ["KindRoIHeads"]


class KindRoIHeads(RoIHeads):
    """Faster R-CNN's box head, scoring boxes by target-or-not and naming the kind apart.

    Training is torchvision's (softmax over background and every kind). At inference
    each RoI gives one box: the regression of its most likely kind, scored by
    ``1 - p(background)``, labelled with that kind, ``kind_scores`` its share
    ``p(kind) / (1 - p(background))`` and ``kind_probs`` every kind's share (a row a box,
    summing to 1); boxes are then suppressed across kinds (one box a hyperbola). With one
    kind this is torchvision's own post-processing.
    """

    def forward(self, features, proposals, image_shapes, targets=None):
        if self.training:
            return super().forward(features, proposals, image_shapes, targets)
        feats = self.box_head(self.box_roi_pool(features, proposals, image_shapes))
        class_logits, box_regression = self.box_predictor(feats)
        pred_boxes = self.box_coder.decode(box_regression, proposals)  # (N, classes, 4)
        return self.postprocess(class_logits, pred_boxes, proposals, image_shapes), {}

    def postprocess(self, class_logits, pred_boxes, proposals, image_shapes) -> list[dict]:
        """Per image: ``boxes``, ``labels``, ``scores``, ``kind_scores`` and ``kind_probs`` from the RoIs' logits and
        decoded boxes."""
        probs = F.softmax(class_logits, -1)
        fg = probs[:, 1:]
        score = fg.sum(dim=1)
        best, kind = fg.max(dim=1)
        label = kind + 1
        box = pred_boxes[torch.arange(pred_boxes.shape[0], device=pred_boxes.device), label]
        probs = fg / score.clamp_min(1e-12)[:, None]
        share = best / score.clamp_min(1e-12)
        result = []
        counts = [p.shape[0] for p in proposals]
        for b, s, lab, sh, pr, shape in zip(box.split(counts), score.split(counts), label.split(counts),
                                            share.split(counts), probs.split(counts), image_shapes):
            b = box_ops.clip_boxes_to_image(b, shape)
            keep = torch.where(s > self.score_thresh)[0]
            b, s, lab, sh, pr = b[keep], s[keep], lab[keep], sh[keep], pr[keep]
            keep = box_ops.remove_small_boxes(b, min_size=1e-2)
            b, s, lab, sh, pr = b[keep], s[keep], lab[keep], sh[keep], pr[keep]
            keep = box_ops.nms(b, s, self.nms_thresh)[: self.detections_per_img]
            result.append({"boxes": b[keep], "labels": lab[keep], "scores": s[keep], "kind_scores": sh[keep],
                           "kind_probs": pr[keep]})
        return result
