"""Shading, the stage after :mod:`kadv.render.surface`: a hit's colour from its albedo and the
light it receives, view-independent (no head-light, no specular term; the differentiable
reprojection relies on it).

Direct lighting is albedo x (ambient + Lambertian world lights). Baked lighting is albedo x baked
irradiance (:mod:`kadv.render.irradiance`) plus the point, spot and sun lights' sharp shadows,
tone-mapped; a ray that leaves the scene sees the sky the bake was lit by, and one that meets an
area emitter first sees its glow.

The per-sample arithmetic runs in torch, float32 for colours, normals and lights (8-bit textures
need no more) and float64 for texture coordinates, whose tiling can reach hundreds of repeats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch
from torch.nn import functional as F

from kadv.geometry.vector import dot
from kadv.render.bake import BakeConfig
from kadv.render.colour import tone_map
from kadv.render.irradiance import BakedLighting
from kadv.render.lights import DeltaLights, Sky, scene_lights, sky_emitters
from kadv.render.surface import RayHits, Surfaces, first_hits

__all__ = ["Shader", "Shading", "shade"]


@dataclass(frozen=True)
class Shading:
    """Shading parameters.

    Attributes:
        ambient: constant term in [0, 1].
        diffuse: weight of the Lambertian term, split evenly over the lights.
        lights: (L, 3) world positions; None uses the scene's emitters, else a light placed from
            the scene bounds.
        background: RGB of rays that hit nothing.
        lighting: ``"direct"`` (ambient + Lambertian lights, no shadows) or ``"baked"`` (the
            scene's emitters with shadows and diffuse inter-reflection, baked once per scene). The
            commands default to ``"baked"`` (``render.lighting``); a renderer built here shades
            ``"direct"`` unless asked, so that building one never starts a bake of minutes.
        bake: the bake's settings, for ``lighting="baked"``.
    """

    ambient: float = 0.45
    diffuse: float = 0.55
    lights: tuple[tuple[float, float, float], ...] | None = None
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lighting: str = "direct"
    bake: BakeConfig = field(default_factory=BakeConfig)

    def __post_init__(self) -> None:
        if self.lighting not in ("direct", "baked"):
            raise ValueError(f"render.lighting must be 'direct' or 'baked', got {self.lighting!r}")


def shade(
    shading: Shading, lights: torch.Tensor, points: torch.Tensor, normals: torch.Tensor, base_colour: torch.Tensor
) -> torch.Tensor:
    """Shaded RGB (N, 3) in [0, 1] of surface points (N, 3) with unit normals (N, 3) facing the
    viewer side, under ``lights`` (L, 3)."""
    to_lights = F.normalize(lights[None, :, :] - points[:, None, :], dim=-1, eps=1e-9)
    lambert = dot(to_lights, normals[:, None, :]).clamp_min(0.0).mean(dim=1)
    light = shading.ambient + shading.diffuse * lambert
    return (base_colour * light[:, None]).clamp(0.0, 1.0)


class Shader:
    """Colours of hits on ``surfaces`` under ``shading``, with the scene's ``baked`` lighting (None:
    direct lighting), computed on the surfaces' device.

    Scene data the shading reads (lights, emitters, their colours, the sky) are tensors made once,
    here, on that device.
    """

    def __init__(self, surfaces: Surfaces, shading: Shading, baked: BakedLighting | None = None) -> None:
        scene, device = surfaces.scene, surfaces.device
        self.surfaces, self.shading, self.baked = surfaces, shading, baked
        self.lights = scene_lights(scene, shading.lights)
        self._lights = torch.from_numpy(self.lights.astype(np.float32)).to(device)
        self._background = torch.tensor(shading.background, dtype=torch.float32).to(device)
        self._emitter_caster = None
        if baked is not None:
            self._delta_lights = DeltaLights(scene.emitters, device)
            self._sky = Sky(sky_emitters(scene), device)
            emitters = scene.emitters.area_triangles
            if len(emitters):  # the file's lamps and glowing panels, seen as a camera sees them
                self._emitter_caster = surfaces.caster_of(
                    emitters.reshape(-1, 3), np.arange(3 * len(emitters)).reshape(-1, 3)
                )
                cross = np.cross(emitters[:, 1] - emitters[:, 0], emitters[:, 2] - emitters[:, 0])
                self._emitter_normals = torch.from_numpy(cross).to(device)
                glow = tone_map(torch.from_numpy(scene.emitters.area_radiance * baked.exposure)).float()
                self._emitter_colour = glow.to(device)

    def shade(
        self,
        hits: RayHits,
        origins: torch.Tensor,
        directions: torch.Tensor,
        pixel_angle: float,
        colour: bool = True,
        geometry: bool = True,
    ) -> dict[str, torch.Tensor]:
        """Shade hits of rays (N, 3) float64 on the surfaces' device; ``pixel_angle`` (radians per
        sample) selects the texture mip level.

        Returns "rgb" (N, 3) float32 and, with ``geometry``, the masked "points", "normals" (N, 3)
        float32 and "back_face" (N,) bool, on the same device. With ``colour`` False "rgb" is the
        background: the caller takes colour from other rays.
        """
        # Every ray is shaded (a miss as a point on triangle 0 at the eye) and misses are masked at
        # the end: indoors nearly every ray hits, and compacting the hits would cost more (and, on a
        # GPU, a wait for their count).
        hit = hits.hit
        ids = hits.triangle_ids.clamp_min(0)
        bary = hits.barycentrics
        t = torch.where(hit, hits.t.double(), 0.0)
        facing = self.surfaces.facing(ids, directions)
        back = hit & (facing > 0)
        # hit points and shading normals, where something reads them: the maps, Lambert's term or
        # the delta lights (baked light alone needs neither)
        lit_at_points = self.baked is None or not self._delta_lights.empty
        if geometry or (colour and lit_at_points):
            points = origins + directions * t[:, None]
            normals = F.normalize(self.surfaces.interpolate(self.surfaces.normals, ids, bary), dim=1, eps=1e-12)
            normals = torch.where(back[:, None], -normals, normals)
        rgb = self._background.expand(len(t), 3)
        if colour:
            length = directions.norm(dim=1)
            incidence = facing.abs() / length
            # geometric mean of the footprint's two axes (one stretched by 1 / cos incidence)
            footprint = t * length * pixel_angle / incidence.clamp_min(0.05).sqrt()
            base = self.surfaces.albedo(ids, bary, footprint.float())
            background = self._background
            if self.baked is None:
                shaded = shade(self.shading, self._lights, points.float(), normals, base)
            else:
                # the lattice weights in float64: a hit's place between lattice points is a small difference
                irradiance = self.baked.irradiance_at(ids, bary.double(), back)
                if not self._delta_lights.empty:
                    irradiance = irradiance + self._delta_irradiance(points, directions, normals, hit)
                shaded = tone_map(self.surfaces.reflectance(ids, base) * irradiance * (self.baked.exposure / math.pi))
                # a ray that leaves the scene sees the sky the bake was lit by
                sky = self._sky(F.normalize(directions, dim=1))
                background = tone_map((sky * self.baked.exposure).float())
            rgb = torch.where(hit[:, None], shaded, background)
            if self._emitter_caster is not None:
                rgb = self._emitters_seen(rgb, hits, origins, directions)
        maps = {"rgb": rgb.contiguous()}
        if geometry:
            maps.update(
                points=torch.where(hit[:, None], points.float(), 0.0),
                normals=torch.where(hit[:, None], normals, 0.0),
                back_face=back,
            )
        return maps

    def _delta_irradiance(
        self, points: torch.Tensor, directions: torch.Tensor, normals: torch.Tensor, hit: torch.Tensor
    ) -> torch.Tensor:
        """(N, 3) float32 irradiance at the hits (points (N, 3) float64) from the scene's point, spot
        and sun lights, with one shadow ray each (zero on misses)."""
        facing = normals.double()
        # the side the ray arrived from, whatever the file's normals say
        facing = torch.where((dot(facing, directions) > 0)[:, None], -facing, facing)
        irradiance = self._delta_lights.irradiance(self.surfaces, points, facing)
        return torch.where(hit[:, None], irradiance, 0.0).float()

    def _emitters_seen(
        self, rgb: torch.Tensor, hits: RayHits, origins: torch.Tensor, directions: torch.Tensor
    ) -> torch.Tensor:
        """``rgb`` (N, 3) with the colour of an area emitter wherever a ray meets one before any
        surface: its radiance on its emitting side, black behind. Emitters are no geometry (they
        carry no depth): only the colour shows them."""
        emitter = first_hits(self._emitter_caster, origins, directions)
        seen = emitter.hit & (emitter.t < torch.where(hits.hit, hits.t, torch.inf))
        ids = emitter.triangle_ids.clamp_min(0)
        facing = dot(self._emitter_normals.index_select(0, ids), directions) < 0
        glow = self._emitter_colour.index_select(0, ids) * facing[:, None]
        return torch.where(seen[:, None], glow, rgb)
