"""kadv: adversarial camera viewpoints for monocular depth estimation models."""
from __future__ import annotations

from kadv.geometry import Camera, intrinsics_from_fov, look_at
from kadv.models import DepthModel, load_model
from kadv.render import DiffRenderConfig, DifferentiableRenderer, ExactRenderer, RenderOutput, Shading
from kadv.scenes import Material, Scene, box_room, load_scene

__all__ = [
    "Camera",
    "DepthModel",
    "DiffRenderConfig",
    "DifferentiableRenderer",
    "ExactRenderer",
    "Material",
    "RenderOutput",
    "Scene",
    "Shading",
    "box_room",
    "intrinsics_from_fov",
    "load_model",
    "load_scene",
    "look_at",
]
__version__ = "0.1.0"
