"""Output kinds, comparison spaces, min-max normalisation and the least-squares alignments: scale
and shift, or scale alone.

All maps are (B, 1, H, W); ``mask`` (B, 1, H, W) bool marks valid pixels.
"""

from __future__ import annotations

import torch

__all__ = [
    "ALIGNMENTS",
    "KINDS",
    "SPACES",
    "align_scale",
    "align_scale_shift",
    "check_alignment",
    "check_kind",
    "kind_fit",
    "minmax_normalize",
    "to_comparison_space",
]

_EPS = 1e-8

# how a prediction is fitted to the ground truth before it is scored (``loss.alignment``): least
# squares on scale and shift, or on scale alone, in the loss's space; or not at all (metric depth)
ALIGNMENTS = ("scale_shift", "scale", "none")
SPACES = ("disparity", "depth")

# what a model's prediction holds (``model.output_kind``), with the space its values live in and
# the space and alignment its figures are fitted in by default: its own ambiguity in its own space
KINDS = {
    "disparity": ("disparity", "disparity", "scale_shift"),  # relative inverse depth, affine-invariant
    "depth": ("depth", "disparity", "scale_shift"),  # metric depth, scored as the study scored it
    "affine_depth": ("depth", "depth", "scale_shift"),  # depth up to scale and shift (Marigold)
    "scale_depth": ("depth", "depth", "scale"),  # depth up to scale
}
_KIND_WORDS = {
    "disparity": "relative disparity",
    "affine_depth": "affine-invariant depth",
    "scale_depth": "scale-invariant depth",
}


def check_kind(kind: str, key: str = "output_kind") -> str:
    """``kind`` if it is one of :data:`KINDS`, else a ``ValueError`` naming ``key`` and the kinds."""
    if kind not in KINDS:
        raise ValueError(f"{key} must be one of {', '.join(KINDS)}, got {kind!r}")
    return kind


def kind_fit(kind: str, space: str | None = None, alignment: str | None = None) -> tuple[str, str]:
    """The (space, alignment) a prediction of ``kind`` is fitted in: the ones given, else the
    kind's own (disparity and metric depth: scale and shift in disparity space; affine-invariant
    depth: scale and shift in depth space; scale-invariant depth: scale in depth space).

    Examples:
        >>> kind_fit("affine_depth"), kind_fit("scale_depth"), kind_fit("depth", alignment="none")
        (('depth', 'scale_shift'), ('depth', 'scale'), ('disparity', 'none'))
    """
    _, own_space, own_alignment = KINDS[check_kind(kind)]
    return space or own_space, alignment or own_alignment


def check_alignment(alignment: str, prediction_kind: str, model: str = "the model") -> None:
    """Refuse an unknown alignment, or ``none`` for a prediction that is not metric depth, naming
    the model and what it outputs."""
    if alignment not in ALIGNMENTS:
        raise ValueError(f"loss.alignment must be one of {', '.join(ALIGNMENTS)}, got {alignment!r}")
    if alignment == "none" and prediction_kind != "depth":
        raise ValueError(
            f"loss.alignment=none scores the prediction as metric depth, but {model} outputs "
            f"{_KIND_WORDS.get(prediction_kind, prediction_kind)}: use scale_shift or scale"
        )


def to_comparison_space(values: torch.Tensor, kind: str, space: str, mask: torch.Tensor) -> torch.Tensor:
    """Convert a depth or disparity map to ``space`` ("disparity" or "depth"); 0 at invalid pixels.

    Args:
        values: (B, 1, H, W) map.
        kind: what ``values`` holds: "depth" (metres), "disparity" (relative inverse depth), or
            depth up to an affine map or a scale ("affine_depth", "scale_depth": depth space).
        space: the space to compare in.
        mask: (B, 1, H, W) valid pixels.

    Examples:
        >>> depth = torch.tensor([[[[2.0, 4.0], [0.0, 8.0]]]])
        >>> to_comparison_space(depth, "depth", "disparity", depth > 0)  # 0 where invalid
        tensor([[[[0.5000, 0.2500],
                  [0.0000, 0.1250]]]])
    """
    if space not in SPACES:
        raise ValueError(f"space must be 'depth' or 'disparity', got {space!r}")
    own = KINDS[check_kind(kind, "kind")][0]
    valid = mask & (values > _EPS) if own != space else mask
    converted = values if own == space else 1.0 / values.clamp_min(_EPS)
    return torch.where(valid, converted, torch.zeros_like(converted))


def minmax_normalize(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Rescale each map's valid pixels to [0, 1] (min -> 0, max -> 1); invalid pixels -> 0.

    Examples:
        >>> values = torch.tensor([[[[2.0, 4.0], [6.0, 10.0]]]])
        >>> minmax_normalize(values, torch.ones_like(values, dtype=torch.bool))
        tensor([[[[0.0000, 0.2500],
                  [0.5000, 1.0000]]]])
    """
    big = torch.finfo(values.dtype).max
    low = torch.where(mask, values, torch.full_like(values, big)).amin(dim=(1, 2, 3), keepdim=True)
    high = torch.where(mask, values, torch.full_like(values, -big)).amax(dim=(1, 2, 3), keepdim=True)
    scaled = (values - low) / (high - low).clamp_min(_EPS)
    return torch.where(mask, scaled, torch.zeros_like(scaled))


def align_scale_shift(prediction: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """s * prediction + t with (s, t) per map minimising the squared error to ``target`` on ``mask``.

    Closed-form normal equations, differentiable in both maps.

    Examples:
        >>> target = torch.arange(16.0, dtype=torch.float64).reshape(1, 1, 4, 4)
        >>> mask = torch.ones_like(target, dtype=torch.bool)
        >>> torch.allclose(align_scale_shift(0.5 * target - 3.0, target, mask), target)
        True
    """
    weight = mask.to(prediction.dtype)
    count = weight.sum(dim=(1, 2, 3), keepdim=True).clamp_min(1.0)
    mean_p = (weight * prediction).sum(dim=(1, 2, 3), keepdim=True) / count
    mean_t = (weight * target).sum(dim=(1, 2, 3), keepdim=True) / count
    centred_p = (prediction - mean_p) * weight
    covariance = (centred_p * (target - mean_t)).sum(dim=(1, 2, 3), keepdim=True)
    variance = (centred_p * centred_p).sum(dim=(1, 2, 3), keepdim=True)
    scale = covariance / variance.clamp_min(_EPS)
    return scale * (prediction - mean_p) + mean_t


def align_scale(prediction: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """s * prediction with s per map minimising the squared error to ``target`` on ``mask``;
    differentiable in both maps.

    Examples:
        >>> target = 1.0 + torch.arange(16.0, dtype=torch.float64).reshape(1, 1, 4, 4)
        >>> mask = torch.ones_like(target, dtype=torch.bool)
        >>> torch.allclose(align_scale(0.5 * target, target, mask), target)
        True
        >>> torch.allclose(align_scale(target - 3.0, target, mask), target)  # a shift stays
        False
    """
    weight = mask.to(prediction.dtype)
    covariance = (weight * prediction * target).sum(dim=(1, 2, 3), keepdim=True)
    variance = (weight * prediction * prediction).sum(dim=(1, 2, 3), keepdim=True)
    return covariance / variance.clamp_min(_EPS) * prediction
