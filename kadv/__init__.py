"""kadv: adversarial camera viewpoints for monocular depth estimation models.

The names below load on first use, so that ``import kadv.runtime`` runs before torch is imported.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from kadv._lazy import lazy_exports

_EXPORTS = {
    "Camera": "kadv.geometry",
    "DepthModel": "kadv.models",
    "DiffRenderConfig": "kadv.render",
    "DifferentiableRenderer": "kadv.render",
    "ExactRenderer": "kadv.render",
    "Material": "kadv.scenes",
    "RenderOutput": "kadv.render",
    "Scene": "kadv.scenes",
    "Shading": "kadv.render",
    "Study": "kadv.attack",
    "StudySettings": "kadv.attack",
    "box_room": "kadv.scenes",
    "intrinsics_from_fov": "kadv.geometry",
    "load_model": "kadv.models",
    "load_scene": "kadv.scenes",
    "look_at": "kadv.geometry",
    "procedural_room": "kadv.scenes",
}

if TYPE_CHECKING:  # the same names, for type checkers and the API reference
    from kadv.attack import Study, StudySettings
    from kadv.geometry import Camera, intrinsics_from_fov, look_at
    from kadv.models import DepthModel, load_model
    from kadv.render import DifferentiableRenderer, DiffRenderConfig, ExactRenderer, RenderOutput, Shading
    from kadv.scenes import Material, Scene, box_room, load_scene, procedural_room

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
    "Study",
    "StudySettings",
    "box_room",
    "intrinsics_from_fov",
    "load_model",
    "load_scene",
    "look_at",
    "procedural_room",
]
__version__ = "0.1.0"

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
