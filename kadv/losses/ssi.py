"""MiDaS's scale-and-shift-invariant loss, for training depth models (kadv-tiny)."""

from __future__ import annotations

import torch

from kadv.losses.align import align_scale_shift, to_comparison_space

__all__ = ["gradient_matching", "ssi_loss"]


def gradient_matching(residual: torch.Tensor, mask: torch.Tensor, scales: int) -> torch.Tensor:
    """Mean |d/dx| + |d/dy| of the residual over pairs of valid pixels, summed over dyadic scales; (B,).

    Examples:
        >>> residual = torch.full((1, 1, 8, 8), 0.3, dtype=torch.float64)  # a constant offset has no gradient
        >>> gradient_matching(residual, torch.ones_like(residual, dtype=torch.bool), scales=2).tolist()
        [0.0]
    """
    total = residual.new_zeros(residual.shape[0])
    for level in range(scales):
        step = 2**level
        r, m = residual[..., ::step, ::step], mask[..., ::step, ::step].to(residual.dtype)
        pairs_x, pairs_y = m[..., 1:] * m[..., :-1], m[..., 1:, :] * m[..., :-1, :]
        gradient = (pairs_x * (r[..., 1:] - r[..., :-1]).abs()).sum(dim=(1, 2, 3))
        gradient = gradient + (pairs_y * (r[..., 1:, :] - r[..., :-1, :]).abs()).sum(dim=(1, 2, 3))
        total = total + gradient / (pairs_x.sum(dim=(1, 2, 3)) + pairs_y.sum(dim=(1, 2, 3))).clamp_min(1.0)
    return total


def ssi_loss(
    prediction: torch.Tensor, gt_depth: torch.Tensor, mask: torch.Tensor, gradient_weight: float = 0.0, scales: int = 4
) -> torch.Tensor:
    """MiDaS-style scale-and-shift-invariant loss in disparity space.

    With d the ground-truth disparity and r = (align(pred) - d) / mean(d): mean |r| plus
    ``gradient_weight`` times the multi-scale gradient-matching term of MiDaS on r, which rewards
    sharp, well placed discontinuities that the mean error alone barely notices.

    Examples:
        >>> depth = 1.0 + torch.arange(64.0, dtype=torch.float64).reshape(1, 1, 8, 8) / 16
        >>> mask = torch.ones_like(depth, dtype=torch.bool)
        >>> disparity = 3.0 / depth - 0.1  # right up to scale and shift
        >>> ssi_loss(disparity, depth, mask, gradient_weight=0.5).abs().item() < 1e-9
        True
        >>> ssi_loss(depth, depth, mask).item() > 0.0  # depth read as disparity is wrong
        True
    """
    target = to_comparison_space(gt_depth, "depth", "disparity", mask)
    weight = mask.to(prediction.dtype)
    count = weight.sum(dim=(1, 2, 3)).clamp_min(1.0)
    scale = ((weight * target).sum(dim=(1, 2, 3)) / count).clamp_min(1e-6)
    residual = weight * (align_scale_shift(prediction, target, mask) - target) / scale[:, None, None, None]
    loss = residual.abs().sum(dim=(1, 2, 3)) / count
    if gradient_weight > 0:
        loss = loss + gradient_weight * gradient_matching(residual, mask, scales)
    return loss.mean()
