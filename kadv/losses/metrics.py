"""Standard depth metrics after an alignment (``loss.alignment``: scale and shift, or scale alone,
or none, for metric depth), fitted by default with the prediction kind's own ambiguity in its own
space (:func:`kadv.losses.kind_fit`)."""

from __future__ import annotations

import torch

from kadv.losses.align import align_scale, align_scale_shift, check_alignment, kind_fit, to_comparison_space

__all__ = ["aligned_depth", "aligned_on_valid", "depth_metrics", "mean_on_valid"]


def aligned_depth(
    prediction: torch.Tensor,
    gt_depth: torch.Tensor,
    mask: torch.Tensor,
    prediction_kind: str = "disparity",
    space: str | None = None,
    alignment: str | None = None,
) -> torch.Tensor:
    """The prediction as metric depth (B, 1, H, W): converted to ``space``, aligned to the ground
    truth there by least squares on ``mask`` (``alignment``: on scale and shift, or on scale
    alone), and converted back; under ``none``, a metric depth prediction as it is (a value at or
    below 0 as a depth of 1e-8 m: wrong). ``space`` and ``alignment`` None: the kind's own
    (:func:`kadv.losses.kind_fit`). Differentiable in both maps.

    Aligned values are clamped at the end of the ground truth's range on the side where depth would
    turn negative (disparity at 1/max(gt), depth at min(gt)), so a prediction that needs a negative
    depth comes out as a ground-truth depth rather than being dropped.

    Examples:
        >>> depth = 1.0 + torch.arange(16.0, dtype=torch.float64).reshape(1, 1, 4, 4) / 4
        >>> mask = torch.ones_like(depth, dtype=torch.bool)
        >>> disparity = 2.0 / depth + 1.0  # right up to scale and shift
        >>> torch.allclose(aligned_depth(disparity, depth, mask, "disparity"), depth)
        True
    """
    space, alignment = kind_fit(prediction_kind, space, alignment)
    check_alignment(alignment, prediction_kind)
    if alignment == "none":
        return prediction.clamp_min(1e-8)
    target = to_comparison_space(gt_depth, "depth", space, mask)
    fit = align_scale_shift if alignment == "scale_shift" else align_scale
    aligned = fit(to_comparison_space(prediction, prediction_kind, space, mask), target, mask)
    if space == "depth":
        floor = torch.where(mask, gt_depth, torch.full_like(gt_depth, torch.inf)).amin(dim=(1, 2, 3), keepdim=True)
        return torch.maximum(aligned, floor)
    floor = 1.0 / torch.where(mask, gt_depth, torch.zeros_like(gt_depth)).amax(dim=(1, 2, 3), keepdim=True)
    return 1.0 / torch.maximum(aligned, floor)


def aligned_on_valid(
    prediction: torch.Tensor,
    gt_depth: torch.Tensor,
    mask: torch.Tensor,
    prediction_kind: str = "disparity",
    space: str | None = None,
    min_depth: float = 1e-3,
    alignment: str | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """What the metrics and the aligned losses score on: the valid pixels (ground truth above
    ``min_depth``), their count per map (B,), the ground truth with 1 elsewhere (safe to divide by),
    and the prediction as :func:`aligned_depth` aligns it in ``space``."""
    mask = mask & (gt_depth > min_depth)
    count = mask.to(gt_depth.dtype).sum(dim=(1, 2, 3)).clamp_min(1.0)
    safe_gt = torch.where(mask, gt_depth, torch.ones_like(gt_depth))
    return mask, count, safe_gt, aligned_depth(prediction, gt_depth, mask, prediction_kind, space, alignment)


def mean_on_valid(values: torch.Tensor, mask: torch.Tensor, count: torch.Tensor) -> torch.Tensor:
    """Mean (B,) of per-pixel ``values`` (B, 1, H, W) over ``mask``, ``count`` pixels per map."""
    return torch.where(mask, values, torch.zeros_like(values)).sum(dim=(1, 2, 3)) / count


def depth_metrics(
    prediction: torch.Tensor,
    gt_depth: torch.Tensor,
    mask: torch.Tensor,
    prediction_kind: str = "disparity",
    min_depth: float = 1e-3,
    alignment: str | None = None,
    space: str | None = None,
) -> dict[str, torch.Tensor]:
    """delta1/2/3, abs_rel and rmse per map (B,) on valid pixels.

    The prediction is aligned as :func:`aligned_depth` does, so a prediction that needs a
    negative depth counts as wrong rather than being dropped.

    Args:
        prediction: (B, 1, H, W) model output.
        gt_depth: (B, 1, H, W) z-depth in metres.
        mask: (B, 1, H, W) valid ground-truth pixels.
        prediction_kind: one of :data:`kadv.losses.KINDS`: "disparity" (relative,
            affine-invariant), "depth" (metric), "affine_depth" or "scale_depth".
        min_depth: ground truth below this is treated as invalid.
        alignment: ``scale_shift``, ``scale`` or ``none`` (a metric depth prediction as it is);
            None: the kind's own.
        space: where the alignment is fitted, ``disparity`` or ``depth``; None: the kind's own.

    Examples:
        >>> depth = 1.0 + torch.arange(16.0, dtype=torch.float64).reshape(1, 1, 4, 4) / 4
        >>> mask = torch.ones_like(depth, dtype=torch.bool)
        >>> metrics = depth_metrics(2.0 / depth + 1.0, depth, mask, "disparity")
        >>> metrics["delta1"].tolist(), metrics["abs_rel"].abs().max().item() < 1e-9
        ([1.0], True)
    """
    mask, count, safe_gt, pred_depth = aligned_on_valid(
        prediction, gt_depth, mask, prediction_kind, space, min_depth=min_depth, alignment=alignment
    )
    ratio = torch.maximum(pred_depth / safe_gt, safe_gt / pred_depth)
    result = {f"delta{k}": mean_on_valid((ratio < 1.25**k).to(gt_depth.dtype), mask, count) for k in (1, 2, 3)}
    result["abs_rel"] = mean_on_valid((pred_depth - safe_gt).abs() / safe_gt, mask, count)
    result["rmse"] = mean_on_valid((pred_depth - safe_gt) ** 2, mask, count).sqrt()
    return result
