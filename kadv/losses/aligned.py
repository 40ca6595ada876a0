"""Attack losses on the failure users report: AbsRel and a smooth delta1 error share, both after
the alignment that scores the prediction (:func:`kadv.losses.aligned_depth`).

Unlike L_depth, which compares min-max normalised maps, these see the prediction as the metrics
do, so a search that raises them lowers the reported delta1 (or raises AbsRel) directly.
"""

from __future__ import annotations

import math

import torch

from kadv.losses.metrics import aligned_on_valid, mean_on_valid

__all__ = ["ALIGNED_LOSSES", "DELTA1_TEMPERATURE", "AlignedLoss", "absrel_loss", "soft_delta1_loss"]

# Width of the smooth delta1 step in log-ratio units: |log(pred / gt)| crosses log(1.25) = 0.223
# over about +-2 temperatures (0.1, a ratio of 1.12 to 1.39), so pixels near the threshold pass a
# gradient and pixels far from it count as right or wrong.
DELTA1_TEMPERATURE = 0.05


def _check_temperature(temperature: float) -> None:
    if not (math.isfinite(temperature) and temperature > 0):
        raise ValueError(f"loss.temperature must be positive, got {temperature}")


def absrel_loss(
    prediction: torch.Tensor,
    gt_depth: torch.Tensor,
    mask: torch.Tensor,
    prediction_kind: str = "disparity",
    space: str | None = None,
    min_depth: float = 1e-3,
    alignment: str | None = None,
) -> torch.Tensor:
    """Mean |aligned - gt| / gt over valid pixels (B,); the ``abs_rel`` of
    :func:`kadv.losses.depth_metrics` in the same space and alignment (None: the kind's own).

    Examples:
        >>> depth = 1.0 + torch.arange(16.0, dtype=torch.float64).reshape(1, 1, 4, 4) / 4
        >>> mask = torch.ones_like(depth, dtype=torch.bool)
        >>> absrel_loss(2.0 / depth + 1.0, depth, mask).abs().item() < 1e-9  # right up to scale and shift
        True
    """
    mask, count, safe_gt, aligned = aligned_on_valid(
        prediction, gt_depth, mask, prediction_kind, space, min_depth, alignment
    )
    return mean_on_valid((aligned - safe_gt).abs() / safe_gt, mask, count)


def soft_delta1_loss(
    prediction: torch.Tensor,
    gt_depth: torch.Tensor,
    mask: torch.Tensor,
    prediction_kind: str = "disparity",
    space: str | None = None,
    temperature: float = DELTA1_TEMPERATURE,
    min_depth: float = 1e-3,
    alignment: str | None = None,
) -> torch.Tensor:
    """A smooth share of pixels that delta1 counts wrong (B,): per pixel
    sigmoid((|log(aligned / gt)| - log 1.25) / temperature), rescaled so that a perfect prediction
    scores 0 and an infinitely wrong one 1. As temperature -> 0 it tends to 1 - delta1.

    Examples:
        >>> depth = 1.0 + torch.arange(16.0, dtype=torch.float64).reshape(1, 1, 4, 4) / 4
        >>> mask = torch.ones_like(depth, dtype=torch.bool)
        >>> soft_delta1_loss(2.0 / depth + 1.0, depth, mask).abs().item() < 1e-9
        True
    """
    _check_temperature(temperature)
    mask, count, safe_gt, aligned = aligned_on_valid(
        prediction, gt_depth, mask, prediction_kind, space, min_depth, alignment
    )
    log_ratio = torch.log(aligned / safe_gt).abs()
    margin = math.log(1.25)
    floor = torch.sigmoid(torch.tensor(-margin / temperature, dtype=log_ratio.dtype))
    wrong = (torch.sigmoid((log_ratio - margin) / temperature) - floor) / (1.0 - floor)
    return mean_on_valid(wrong, mask, count)


# the loss.kind values of the aligned losses
ALIGNED_LOSSES = ("absrel", "delta1")


class AlignedLoss:
    """An attack loss on the aligned prediction, as the objective calls it.

    Args:
        kind: "absrel" or "delta1".
        temperature: the smooth delta1's step width (see :data:`DELTA1_TEMPERATURE`).
    """

    def __init__(self, kind: str, temperature: float = DELTA1_TEMPERATURE) -> None:
        if kind not in ALIGNED_LOSSES:
            raise ValueError(f"loss.kind must be one of {', '.join(ALIGNED_LOSSES)}, got {kind!r}")
        _check_temperature(temperature)
        self.kind, self.temperature = kind, temperature

    def __call__(
        self,
        prediction: torch.Tensor,
        gt_depth: torch.Tensor,
        mask: torch.Tensor,
        prediction_kind: str,
        space: str,
        alignment: str = "scale_shift",
    ) -> torch.Tensor:
        """The loss (B,) of a raw prediction (B, 1, H, W) against z-depth (B, 1, H, W) on ``mask``."""
        if self.kind == "delta1":
            return soft_delta1_loss(
                prediction, gt_depth, mask, prediction_kind, space, self.temperature, alignment=alignment
            )
        return absrel_loss(prediction, gt_depth, mask, prediction_kind, space, alignment=alignment)
