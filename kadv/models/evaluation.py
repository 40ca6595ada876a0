"""A depth model's accuracy on rendered views."""

from __future__ import annotations

import torch

from kadv.datasets import ViewBatch
from kadv.losses import depth_metrics
from kadv.models.base import DepthModel

__all__ = ["evaluate"]


def evaluate(model: DepthModel, views: ViewBatch, batch_size: int = 32) -> float:
    """Mean delta1 (after alignment) of ``model`` on ``views``."""
    scores = []
    with torch.no_grad():
        for start in range(0, len(views.rgb), batch_size):
            part = slice(start, start + batch_size)
            prediction = model(views.rgb[part])
            scores.append(depth_metrics(prediction, views.depth[part], views.mask[part])["delta1"])
    return float(torch.cat(scores).mean())
