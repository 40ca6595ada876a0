"""Depth-discrepancy losses (perceptual VGG-16, SSIM), normalisation, alignment and metrics."""

from __future__ import annotations

from kadv.losses.align import align_scale_shift, minmax_normalize, to_comparison_space
from kadv.losses.metrics import aligned_depth, depth_metrics
from kadv.losses.perceptual import PerceptualLoss, depth_loss, ssim_loss
from kadv.losses.ssi import gradient_matching, ssi_loss
from kadv.losses.vgg import VGG16_TAPS, VGG16_URL, load_vgg16_state_dict, vgg16_features

__all__ = [
    "VGG16_TAPS",
    "VGG16_URL",
    "PerceptualLoss",
    "align_scale_shift",
    "aligned_depth",
    "depth_loss",
    "depth_metrics",
    "gradient_matching",
    "load_vgg16_state_dict",
    "minmax_normalize",
    "ssi_loss",
    "ssim_loss",
    "to_comparison_space",
    "vgg16_features",
]
