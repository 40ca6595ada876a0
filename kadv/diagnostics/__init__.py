"""Validation tools: gradient checks of the differentiable renderer against finite differences."""

from __future__ import annotations

from kadv.diagnostics.gradcheck import (
    FUNCTIONALS,
    GradientCheck,
    check_pose,
    gradient_check_poses,
    occlusion_edge_mask,
    smooth_weights,
    supersampled_maps,
)

__all__ = [
    "FUNCTIONALS",
    "GradientCheck",
    "check_pose",
    "gradient_check_poses",
    "occlusion_edge_mask",
    "smooth_weights",
    "supersampled_maps",
]
