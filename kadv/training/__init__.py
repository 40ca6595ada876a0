"""Training the embedded models on generated rooms (``kadv-train-tiny``, :mod:`kadv.training.tiny`),
and scoring a model on a batch of rendered views (:func:`evaluate`)."""

from __future__ import annotations

from kadv.training.evaluation import evaluate
from kadv.training.tiny import (
    ARCHITECTURES,
    AUGMENTATIONS,
    TARGETS,
    TinyTrainConfig,
    fit,
    load_soup,
    metric_log_loss,
    render_training_views,
    soup,
    train_tiny,
)

__all__ = [
    "ARCHITECTURES",
    "AUGMENTATIONS",
    "TARGETS",
    "TinyTrainConfig",
    "evaluate",
    "fit",
    "load_soup",
    "metric_log_loss",
    "render_training_views",
    "soup",
    "train_tiny",
]
