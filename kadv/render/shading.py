"""Shading, the stage after :mod:`kadv.render.surface`: a hit's colour from its albedo and the
light it receives, view-independent (no head-light, no specular term; the differentiable
reprojection relies on it) unless coats and metals are set to mirror their surroundings
(:attr:`Shading.reflections`).

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
from kadv.render.colour import fresnel_reflectance, srgb_decode, tone_map
from kadv.render.irradiance import BakedLighting
from kadv.render.lights import SURFACE_OFFSET, DeltaLights, Sky, scene_lights, sky_emitters
from kadv.render.surface import RayHits, Surfaces, first_hits
from kadv.scenes.scene import CONDUCTOR_GREY

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
        reflections: with baked lighting, coated surfaces (Mitsuba's plastics) and metals mirror
            what they face, through their GGX lobe and weighted by the coat's Fresnel reflectance
            or the metal's reflectance, in place of the coat's reflection counted as diffuse light
            and of the metal's diffuse look: two more rays per such hit and sample, and their
            colour depends on the view.
    """

    ambient: float = 0.45
    diffuse: float = 0.55
    lights: tuple[tuple[float, float, float], ...] | None = None
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lighting: str = "direct"
    bake: BakeConfig = field(default_factory=BakeConfig)
    reflections: bool = False

    def __post_init__(self) -> None:
        if self.lighting not in ("direct", "baked"):
            raise ValueError(f"render.lighting must be 'direct' or 'baked', got {self.lighting!r}")
        if not isinstance(self.reflections, bool):
            raise ValueError(f"render.shading.reflections must be true or false, got {self.reflections!r}")


def shade(
    shading: Shading, lights: torch.Tensor, points: torch.Tensor, normals: torch.Tensor, base_colour: torch.Tensor
) -> torch.Tensor:
    """Shaded RGB (N, 3) in [0, 1] of surface points (N, 3) with unit normals (N, 3) facing the
    viewer side, under ``lights`` (L, 3)."""
    to_lights = F.normalize(lights[None, :, :] - points[:, None, :], dim=-1, eps=1e-9)
    lambert = dot(to_lights, normals[:, None, :]).clamp_min(0.0).mean(dim=1)
    light = shading.ambient + shading.diffuse * lambert
    return (base_colour * light[:, None]).clamp(0.0, 1.0)


# reflection rays per glossy hit (a coat or a metal) and sample, spread over its GGX lobe
_REFLECTION_RAYS = 2
# devices whose reflections are cast for the glossy hits only, counted (elsewhere every row, masked)
_COMPACTING = ("cpu",)
# Roberts' R2 sequence's constants (1 / g, 1 / g^2, g^3 = g + 1): even 2-D points for any count
_R2 = (1.0 / 1.324717957244746, 1.0 / 1.324717957244746**2)


def _lobe_samples(directions: torch.Tensor, count: int) -> torch.Tensor:
    """(N, count, 2) points in the unit square per ray: the R2 sequence shifted modulo 1 by a hash
    of each ray's unit direction (N, 3), so that a view renders to the same bytes however its rays
    are batched."""
    k = torch.arange(1, count + 1, dtype=torch.float64, device=directions.device)
    sequence = torch.stack([0.5 + k * _R2[0], 0.5 + k * _R2[1]], dim=-1)
    # per row, products and sums in a fixed order (a matrix product's rounding changes with the batch)
    x, y, z = directions.double().unbind(dim=1)
    phases = torch.stack([12.9898 * x + 78.233 * y + 37.719 * z, 39.3467 * x + 11.135 * y + 83.155 * z], dim=-1)
    shift = torch.frac(torch.sin(phases) * 43758.5453).abs()
    return torch.frac(sequence[None] + shift[:, None])


def _ggx_half_vectors(normals: torch.Tensor, alpha: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """(N, K, 3) unit half-vectors drawn from the GGX distribution of roughness ``alpha`` (N,) about
    unit ``normals`` (N, 3), at points ``u`` (N, K, 2) of the unit square (weighted by D cos)."""
    tan2 = alpha[:, None] ** 2 * u[..., 0] / (1.0 - u[..., 0]).clamp_min(1e-12)
    cos_theta = torch.rsqrt(1.0 + tan2)
    sin_theta = (1.0 - cos_theta**2).clamp_min(0.0).sqrt()
    phi = 2.0 * math.pi * u[..., 1]
    helper = torch.where(normals[:, :1].abs() < 0.9, normals.new_tensor([1.0, 0, 0]), normals.new_tensor([0, 1.0, 0]))
    tangent = F.normalize(torch.cross(normals, helper, dim=1), dim=1)
    bitangent = torch.cross(normals, tangent, dim=1)
    return (
        (sin_theta * torch.cos(phi))[..., None] * tangent[:, None]
        + (sin_theta * torch.sin(phi))[..., None] * bitangent[:, None]
        + cos_theta[..., None] * normals[:, None]
    )


def _ggx_weight(
    view: torch.Tensor,
    normals: torch.Tensor,
    halfway: torch.Tensor,
    view_h: torch.Tensor,
    reflected: torch.Tensor,
    alpha: torch.Tensor,
) -> torch.Tensor:
    """(N, K) the GGX microfacet BRDF times the cosine over the sampling density of ``halfway``
    (N, K, 3), without the Fresnel term: Smith's masking G(v) G(l) (v.h) / ((n.v) (n.h)); 0 below
    the surface. ``view`` (N, 3) points from the eye, ``view_h`` (N, K) is -view.h, ``reflected``
    (N, K, 3) points away from the surface."""
    cos_view = (-(view * normals).sum(dim=1)).clamp_min(1e-6)[:, None]
    cos_light = (reflected * normals[:, None]).sum(dim=-1)
    cos_half = (halfway * normals[:, None]).sum(dim=-1).clamp_min(1e-6)

    def masking(cosine: torch.Tensor) -> torch.Tensor:
        tan2 = (1.0 - cosine**2).clamp_min(0.0) / cosine.clamp_min(1e-6) ** 2
        return 2.0 / (1.0 + (1.0 + alpha[:, None] ** 2 * tan2).sqrt())

    weight = masking(cos_view) * masking(cos_light.clamp_min(0.0)) * view_h / (cos_view * cos_half)
    return torch.where(cos_light > 0, weight.clamp(0.0, 1.0), 0.0)


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
                self._emitter_radiance = torch.from_numpy(scene.emitters.area_radiance * baked.exposure).to(device)
                self._emitter_colour = tone_map(self._emitter_radiance).float()

            def per_triangle(values: list) -> torch.Tensor:
                return torch.tensor(values, dtype=torch.float64)[torch.from_numpy(scene.material_ids)].to(device)

            # the relative index of each triangle's coat (0: bare), its metals, and their roughness
            self._coat_ior = per_triangle([material.coat_ior or 0.0 for material in scene.materials])
            self._conductor = per_triangle([material.conductor for material in scene.materials]) > 0
            self._roughness = per_triangle([material.roughness for material in scene.materials])
            self._reflecting = shading.reflections and bool(((self._coat_ior > 0) | self._conductor).any())

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
        # the delta lights or the reflections (baked light alone needs neither)
        lit_at_points = self.baked is None or not self._delta_lights.empty or self._reflecting
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
                radiance = self.surfaces.reflectance(ids, base) * irradiance * (self.baked.exposure / math.pi)
                if self._reflecting:
                    radiance = self._with_reflections(
                        radiance, irradiance, base, ids, points, normals, directions, hit, t, pixel_angle
                    )
                shaded = tone_map(radiance)
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

    def _emitter_glow(
        self, hits: RayHits, origins: torch.Tensor, directions: torch.Tensor, table: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Where rays (N, 3) meet an area emitter before any surface of ``hits`` (N,) bool, and the
        emitter's row of ``table`` (its exposed radiance or its colour) there (N, 3): on its emitting
        side, black behind. Emitters are no geometry (they carry no depth): only the colour shows them."""
        emitter = first_hits(self._emitter_caster, origins, directions)
        seen = emitter.hit & (emitter.t < torch.where(hits.hit, hits.t, torch.inf))
        ids = emitter.triangle_ids.clamp_min(0)
        facing = dot(self._emitter_normals.index_select(0, ids), directions) < 0
        return seen, table.index_select(0, ids) * facing[:, None]

    def _emitters_seen(
        self, rgb: torch.Tensor, hits: RayHits, origins: torch.Tensor, directions: torch.Tensor
    ) -> torch.Tensor:
        """``rgb`` (N, 3) with the colour of an area emitter wherever a ray meets one first."""
        seen, glow = self._emitter_glow(hits, origins, directions, self._emitter_colour)
        return torch.where(seen[:, None], glow, rgb)

    def _with_reflections(
        self,
        radiance: torch.Tensor,
        irradiance: torch.Tensor,
        base: torch.Tensor,
        ids: torch.Tensor,
        points: torch.Tensor,
        normals: torch.Tensor,
        directions: torch.Tensor,
        hit: torch.Tensor,
        t: torch.Tensor,
        pixel_angle: float,
    ) -> torch.Tensor:
        """Exposed radiance (N, 3) of hits with the coats' and metals' reflections (see
        :attr:`Shading.reflections`): what the reflected rays meet, in baked light (the sky, an
        emitter's glow, a surface's diffuse light without its point lights and suns), times the
        coat's Fresnel reflectance in place of the coat's reflection that ``radiance`` counted
        diffuse, or times a metal's reflectance (its display ``base`` (N, 3) over
        :data:`~kadv.scenes.scene.CONDUCTOR_GREY`) in place of its diffuse look."""
        glossy = hit & ((self._coat_ior.index_select(0, ids) > 0) | self._conductor.index_select(0, ids))
        # on the CPU, rays for the glossy hits only; a GPU casts every row's, masked, sooner than it
        # waits for a count
        rows = torch.nonzero(glossy)[:, 0] if self.surfaces.device.type in _COMPACTING else None
        if rows is not None and not len(rows):
            return radiance

        def take(values: torch.Tensor) -> torch.Tensor:
            return values if rows is None else values.index_select(0, rows)

        glossy_ids = take(ids)
        view = F.normalize(take(directions), dim=1)
        normal = take(normals).double()
        count, samples = len(view), _REFLECTION_RAYS
        roughness = self._roughness.index_select(0, glossy_ids)
        halfway = _ggx_half_vectors(normal, roughness, _lobe_samples(view, samples))
        view_h = (-(view[:, None] * halfway).sum(dim=-1)).clamp_min(0.0)  # (R, K)
        reflected = view[:, None] + 2.0 * view_h[..., None] * halfway
        weight = _ggx_weight(view, normal, halfway, view_h, reflected, roughness)
        is_metal = self._conductor.index_select(0, glossy_ids)
        # a metal's Fresnel term is taken as 1: its colour comes from its reflectance below
        ior = torch.where(is_metal, 1.5, self._coat_ior.index_select(0, glossy_ids))
        weight = weight * torch.where(is_metal[:, None], 1.0, fresnel_reflectance(view_h, ior[:, None]))
        origins = (take(points) + SURFACE_OFFSET * normal)[:, None].expand(count, samples, 3).reshape(-1, 3)
        reflected = reflected.reshape(-1, 3)
        live = None if rows is not None else glossy[:, None].expand(count, samples).reshape(-1)
        seen = self.surfaces.cast(origins, reflected, live)
        met = seen.hit
        met_ids = seen.triangle_ids.clamp_min(0)
        back = met & (self.surfaces.facing(met_ids, reflected) > 0)
        # the texture filtered to the reflection's footprint: the eye's distance plus the mirror's
        eye = (take(t) * take(directions).norm(dim=1))[:, None].expand(count, samples).reshape(-1)
        footprint = (eye + torch.where(met, seen.t.double(), 0.0)) * pixel_angle
        met_base = self.surfaces.albedo(met_ids, seen.barycentrics, footprint.float())
        light = self.baked.irradiance_at(met_ids, seen.barycentrics.double(), back)
        surface = self.surfaces.reflectance(met_ids, met_base) * light * (self.baked.exposure / math.pi)
        incoming = torch.where(met[:, None], surface.double(), self._sky(reflected) * self.baked.exposure)
        if self._emitter_caster is not None:
            glowing, glow = self._emitter_glow(seen, origins, reflected, self._emitter_radiance)
            incoming = torch.where(glowing[:, None], glow, incoming)
        mirrored = (weight[..., None] * incoming.reshape(count, samples, 3)).mean(dim=1)
        own = self.surfaces.coats.index_select(0, glossy_ids)[:, 2:3].double() * take(irradiance).double()
        coat_change = mirrored - own * (self.baked.exposure / math.pi)
        reflectance = srgb_decode((take(base).double() / CONDUCTOR_GREY).clamp(0.0, 1.0))
        change = torch.where(is_metal[:, None], reflectance * mirrored - take(radiance).double(), coat_change)
        if rows is None:
            return radiance + torch.where(glossy[:, None], change, 0.0).float()
        return radiance.index_add(0, rows, change.float())
