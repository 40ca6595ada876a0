"""A depth model's accuracy on rendered views."""

from __future__ import annotations

import torch

from kadv.datasets import ViewBatch
from kadv.losses import depth_metrics
from kadv.models.base import DepthModel

__all__ = ["evaluate"]


def evaluate(model: DepthModel, views: ViewBatch, batch_size: int = 32, alignment: str = "scale_shift") -> float:
    """Mean delta1 of ``model`` on ``views``, its prediction aligned by ``alignment``
    (``scale_shift``, ``scale`` or ``none``)."""
    scores = []
    with torch.no_grad():
        for start in range(0, len(views.rgb), batch_size):
            part = slice(start, start + batch_size)
            prediction = model(views.rgb[part])
            kind, truth = model.output_kind, (views.depth[part], views.mask[part])
            scores.append(depth_metrics(prediction, *truth, kind, alignment=alignment)["delta1"])
    return float(torch.cat(scores).mean())
