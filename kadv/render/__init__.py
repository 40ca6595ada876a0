"""Rendering: the exact ray-cast renderer and its shading."""
from __future__ import annotations

from kadv.render.raycast import ExactRenderer, RayHits, RenderOutput
from kadv.render.shading import Shading, sample_texture, scene_lights

__all__ = ["ExactRenderer", "RayHits", "RenderOutput", "Shading", "sample_texture", "scene_lights"]
