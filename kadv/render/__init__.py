"""Rendering: the exact ray-cast renderer, anchor layers, reprojection and the differentiable façade."""

from __future__ import annotations

from kadv.render.dibr import Reprojection, reproject
from kadv.render.differentiable import DifferentiableRenderer, DiffRenderConfig, DiffRenderOutput
from kadv.render.layers import AnchorLayers, render_anchor
from kadv.render.lighting import BakeConfig, BakedLighting, bake_lighting, load_or_bake
from kadv.render.raycast import ExactRenderer, RayHits, RenderOutput
from kadv.render.shading import Shading, sample_texture, scene_lights
from kadv.render.silhouette import EdgePairs, find_edge_pairs, silhouette_term

__all__ = [
    "AnchorLayers",
    "BakeConfig",
    "BakedLighting",
    "DiffRenderConfig",
    "DiffRenderOutput",
    "DifferentiableRenderer",
    "EdgePairs",
    "ExactRenderer",
    "RayHits",
    "RenderOutput",
    "Reprojection",
    "Shading",
    "bake_lighting",
    "find_edge_pairs",
    "load_or_bake",
    "render_anchor",
    "reproject",
    "sample_texture",
    "scene_lights",
    "silhouette_term",
]
