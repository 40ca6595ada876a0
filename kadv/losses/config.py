"""LossConfig: the attacked loss and how its maps meet the ground truth (``conf/loss/``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch

from kadv.losses.aligned import DELTA1_TEMPERATURE, AlignedLoss
from kadv.losses.perceptual import depth_loss

__all__ = ["LossConfig"]


@dataclass(frozen=True)
class LossConfig:
    """The loss a search climbs (``conf/loss/``).

    Attributes:
        kind: ``"delta1"``, ``"absrel"``, ``"ssim"`` or ``"perceptual"`` (:func:`kadv.losses.depth_loss`).
        space: ``"disparity"`` or ``"depth"``: where the maps are compared; None: where the
            model's output kind is fitted (:func:`kadv.losses.kind_fit`: disparity for
            ``disparity`` and ``depth``, depth for ``affine_depth`` and ``scale_depth``).
        alignment: how the prediction meets the ground truth: ``scale_shift``, ``scale`` or
            ``none`` (metric depth as predicted); None: the kind's own (``scale`` for
            ``scale_depth``, ``scale_shift`` otherwise).
        vgg_weights: the perceptual loss's VGG-16 state dict (None: the torch hub's cache).
        window_size: the SSIM loss's window.
        temperature: the smooth delta1's step width, in log-ratio units.
    """

    kind: str = "delta1"
    space: str | None = None
    alignment: str | None = None
    vgg_weights: str | Path | None = None
    window_size: int = 11
    temperature: float = DELTA1_TEMPERATURE

    @property
    def function_key(self) -> tuple:
        """What :meth:`loss` is made from: two configs with one key share one loss function (the
        space and the alignment are the objective's, not the function's)."""
        return (self.kind, self.vgg_weights, self.window_size, self.temperature)

    def loss(self) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor] | AlignedLoss:
        """The loss function (a ``ValueError`` naming the key for a bad kind or window)."""
        return depth_loss(*self.function_key)
