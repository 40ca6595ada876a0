"""kadv: adversarial camera viewpoints for monocular depth estimation models."""
from __future__ import annotations

from kadv.geometry import Camera, intrinsics_from_fov, look_at
from kadv.render import ExactRenderer, RenderOutput, Shading
from kadv.scenes import Material, Scene, box_room, load_scene

__all__ = [
    "Camera",
    "ExactRenderer",
    "Material",
    "RenderOutput",
    "Scene",
    "Shading",
    "box_room",
    "intrinsics_from_fov",
    "load_scene",
    "look_at",
]
__version__ = "0.1.0"
