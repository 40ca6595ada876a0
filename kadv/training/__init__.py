"""Training the embedded models on generated rooms (``kadv-train-tiny``, :mod:`kadv.training.tiny`),
and scoring a model on a batch of rendered views (:func:`evaluate`)."""

from __future__ import annotations

from kadv.training import tiny as _tiny
from kadv.training.evaluation import evaluate as evaluate
from kadv.training.tiny import *  # noqa: F403

__all__ = sorted(["evaluate", *_tiny.__all__])
