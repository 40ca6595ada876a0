"""Rendering: the exact ray-cast renderer, anchor layers, reprojection and the differentiable façade.

The exact renderer's stages, each in its own module: cast (:mod:`~kadv.render.casting`, behind
:mod:`~kadv.render.backends`) -> surface (:mod:`~kadv.render.surface`: what was hit, with
:mod:`~kadv.render.textures`) -> shade (:mod:`~kadv.render.shading`, reading
:mod:`~kadv.render.irradiance` and :mod:`~kadv.render.lights`) -> output
(:mod:`~kadv.render.exact`). The bake (:mod:`~kadv.render.bake`) estimates the irradiance once
per scene with the same surfaces.
"""

from __future__ import annotations

from kadv.render.bake import BakeConfig, bake_lighting, load_or_bake
from kadv.render.dibr import Reprojection, reproject, warp_boxed
from kadv.render.differentiable import DifferentiableRenderer, DiffRenderConfig, DiffRenderOutput
from kadv.render.exact import ExactRenderer, RayHits, RenderOutput
from kadv.render.irradiance import BakedLighting
from kadv.render.layers import AnchorLayers, BoxedLayers, render_anchor
from kadv.render.lights import scene_lights
from kadv.render.shading import Shading
from kadv.render.silhouette import EdgePairs, FoundEdges, find_edge_pairs, silhouette_term, track_edge_pairs
from kadv.render.surface import Surfaces
from kadv.render.textures import sample_texture

__all__ = [
    "AnchorLayers",
    "BakeConfig",
    "BakedLighting",
    "BoxedLayers",
    "DiffRenderConfig",
    "DiffRenderOutput",
    "DifferentiableRenderer",
    "EdgePairs",
    "ExactRenderer",
    "FoundEdges",
    "RayHits",
    "RenderOutput",
    "Reprojection",
    "Shading",
    "Surfaces",
    "bake_lighting",
    "find_edge_pairs",
    "load_or_bake",
    "render_anchor",
    "reproject",
    "sample_texture",
    "scene_lights",
    "silhouette_term",
    "track_edge_pairs",
    "warp_boxed",
]
