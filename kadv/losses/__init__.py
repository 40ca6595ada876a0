"""Depth-discrepancy losses (perceptual VGG-16, SSIM; AbsRel, smooth delta1), normalisation, alignment and metrics."""

from __future__ import annotations

from kadv.losses.align import (
    ALIGNMENTS,
    KINDS,
    SPACES,
    align_scale,
    align_scale_shift,
    check_alignment,
    check_kind,
    kind_fit,
    minmax_normalize,
    to_comparison_space,
)
from kadv.losses.aligned import ALIGNED_LOSSES, DELTA1_TEMPERATURE, AlignedLoss, absrel_loss, soft_delta1_loss
from kadv.losses.config import LossConfig
from kadv.losses.metrics import aligned_depth, depth_metrics
from kadv.losses.perceptual import PerceptualLoss, depth_loss, ssim_loss
from kadv.losses.ssi import gradient_matching, ssi_loss
from kadv.losses.vgg import VGG16_TAPS, VGG16_URL, load_vgg16_state_dict, vgg16_features

__all__ = [
    "ALIGNED_LOSSES",
    "ALIGNMENTS",
    "DELTA1_TEMPERATURE",
    "KINDS",
    "SPACES",
    "VGG16_TAPS",
    "VGG16_URL",
    "AlignedLoss",
    "LossConfig",
    "PerceptualLoss",
    "absrel_loss",
    "align_scale",
    "align_scale_shift",
    "aligned_depth",
    "check_alignment",
    "check_kind",
    "depth_loss",
    "depth_metrics",
    "gradient_matching",
    "kind_fit",
    "load_vgg16_state_dict",
    "minmax_normalize",
    "soft_delta1_loss",
    "ssi_loss",
    "ssim_loss",
    "to_comparison_space",
    "vgg16_features",
]
