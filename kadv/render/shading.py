"""Shading, the stage after :mod:`kadv.render.surface`: a hit's colour from its albedo and the
light it receives, view-independent (no head-light, no specular term; the differentiable
reprojection relies on it). What coats and metals mirror (:attr:`Shading.reflections`) depends on
the view: :meth:`Shader.reflections` estimates it per pixel, and the exact render adds it to the
finished image.

Direct lighting is albedo x (ambient + Lambertian world lights). Baked lighting is albedo x baked
irradiance (:mod:`kadv.render.irradiance`) plus the point, spot and sun lights' sharp shadows,
tone-mapped; a ray that leaves the scene sees the sky the bake was lit by, and one that meets an
area emitter first sees its glow.

The per-sample arithmetic runs in torch, float32 for colours, normals and lights (8-bit textures
need no more) and float64 for texture coordinates, whose tiling can reach hundreds of repeats.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import torch
from kornia.filters import gaussian_blur2d
from torch.nn import functional as F

from kadv.geometry.vector import dot
from kadv.render.bake import BakeConfig
from kadv.render.colour import fresnel_reflectance, srgb_decode, tone_map
from kadv.render.irradiance import BakedLighting
from kadv.render.lights import SURFACE_OFFSET, DeltaLights, Sky, scene_lights, sky_emitters
from kadv.render.surface import RayHits, Surfaces, first_hits
from kadv.scenes.scene import CONDUCTOR_GREY

__all__ = ["LIGHTINGS", "MIRROR_BOUNCES", "Reflections", "Shader", "Shading", "shade"]

LIGHTINGS = ("direct", "baked", "scanned")


@dataclass(frozen=True)
class Shading:
    """Shading parameters.

    Attributes:
        ambient: constant term in [0, 1].
        diffuse: weight of the Lambertian term, split evenly over the lights.
        lights: (L, 3) world positions; None uses the scene's emitters, else a light placed from
            the scene bounds.
        background: RGB of rays that hit nothing (black by default: under ``scanned`` lighting, the
            holes of a scan and the sky above a room without a ceiling).
        lighting: ``"direct"`` (ambient + Lambertian lights, no shadows), ``"baked"`` (the
            scene's emitters with shadows and diffuse inter-reflection, baked once per scene) or
            ``"scanned"`` (a scan's colour shown as the light its sensor captured: vertex colours
            interpolated, or the texel, with no lights, no bake and no reflections). The commands
            default to ``"baked"`` (``render.lighting``); a renderer built here shades
            ``"direct"`` unless asked, so that building one never starts a bake of minutes.
        bake: the bake's settings, for ``lighting="baked"``.
        reflections: with baked lighting, coated surfaces (Mitsuba's plastics) and metals mirror
            what they face, through their GGX lobe and weighted by the coat's Fresnel reflectance
            or the metal's reflectance, in place of the coat's reflection counted as diffuse light
            and of the metal's diffuse look: one more ray per such pixel, whose colour depends on
            the view (the exact render's image has them; anchor layers and the warp do not). On by
            default; False shades coats and metals as diffuse surfaces.
    """

    ambient: float = 0.45
    diffuse: float = 0.55
    lights: tuple[tuple[float, float, float], ...] | None = None
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lighting: str = "direct"
    bake: BakeConfig = field(default_factory=BakeConfig)
    reflections: bool = True

    def __post_init__(self) -> None:
        if self.lighting not in LIGHTINGS:
            raise ValueError(f"render.lighting must be one of {', '.join(LIGHTINGS)}, got {self.lighting!r}")
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


# lobes at most this rough (GGX alpha) mirror sharply: one ray per pixel shows them without noise;
# rougher lobes' single rays are averaged over their neighbours (see Shader.reflections)
SHARP_ROUGHNESS = 0.03
# the width (radians, a Gaussian's sigma) over which rougher lobes' single rays per pixel are
# averaged: _LOBE_SHARE x the lobe's GGX alpha, and at least _REFLECTION_SMOOTHING (about 4 pixels at
# 160 pixels across a 70-degree view). The lobe already blurs what it mirrors over about twice its
# alpha, so half of that adds little blur, while a fixed width showed a rough floor's mirrored
# windows in blotches, too few rays of the wide lobe meeting them (docs/reference_renders.md)
_REFLECTION_SMOOTHING = 0.03
_LOBE_SHARE = 0.5
# a ray between facing mirrors ends after this many bounces, on the last mirror's own shading
MIRROR_BOUNCES = 4
# devices whose reflections are cast for the glossy hits only, counted (elsewhere every row, masked)
_COMPACTING = ("cpu",)
# added to every hash: the first point of Roberts' R2 sequence (1 / g, 1 / g^2 with g^3 = g + 1)
_R2_FIRST = (0.5 + 1.0 / 1.324717957244746, 0.5 + 1.0 / 1.324717957244746**2)


def _smoothing_width(alpha: float) -> float | None:
    """The width (radians) over which a lobe of GGX ``alpha`` is averaged; None: it mirrors sharply."""
    return None if alpha <= SHARP_ROUGHNESS else max(_REFLECTION_SMOOTHING, _LOBE_SHARE * alpha)


def _lobe_samples(directions: torch.Tensor) -> torch.Tensor:
    """(N, 2) a point in the unit square per ray: a hash of each ray's unit direction (N, 3), so that
    a view renders to the same bytes however its rays are batched, shifted modulo 1."""
    # per row, products and sums in a fixed order (a matrix product's rounding changes with the batch)
    x, y, z = directions.double().unbind(dim=1)
    phases = torch.stack([12.9898 * x + 78.233 * y + 37.719 * z, 39.3467 * x + 11.135 * y + 83.155 * z], dim=-1)
    shift = torch.frac(torch.sin(phases) * 43758.5453).abs()
    return torch.frac(shift + shift.new_tensor(_R2_FIRST))


def _ggx_half_vectors(normals: torch.Tensor, alpha: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """(N, 3) unit half-vectors drawn from the GGX distribution of roughness ``alpha`` (N,) about
    unit ``normals`` (N, 3), at points ``u`` (N, 2) of the unit square (weighted by D cos)."""
    tan2 = alpha**2 * u[:, 0] / (1.0 - u[:, 0]).clamp_min(1e-12)
    cos_theta = torch.rsqrt(1.0 + tan2)
    sin_theta = (1.0 - cos_theta**2).clamp_min(0.0).sqrt()
    phi = 2.0 * math.pi * u[:, 1]
    helper = torch.where(normals[:, :1].abs() < 0.9, normals.new_tensor([1.0, 0, 0]), normals.new_tensor([0, 1.0, 0]))
    tangent = F.normalize(torch.cross(normals, helper, dim=1), dim=1)
    bitangent = torch.cross(normals, tangent, dim=1)
    return (
        (sin_theta * torch.cos(phi))[:, None] * tangent
        + (sin_theta * torch.sin(phi))[:, None] * bitangent
        + cos_theta[:, None] * normals
    )


def _ggx_weight(
    view: torch.Tensor,
    normals: torch.Tensor,
    halfway: torch.Tensor,
    view_h: torch.Tensor,
    reflected: torch.Tensor,
    alpha: torch.Tensor,
) -> torch.Tensor:
    """(N,) the GGX microfacet BRDF times the cosine over the sampling density of ``halfway``
    (N, 3), without the Fresnel term: Smith's masking G(v) G(l) (v.h) / ((n.v) (n.h)); 0 below the
    surface. ``view`` (N, 3) points from the eye, ``view_h`` (N,) is -view.h, ``reflected`` (N, 3)
    points away from the surface."""
    cos_view = (-(view * normals).sum(dim=1)).clamp_min(1e-6)
    cos_light = (reflected * normals).sum(dim=1)
    cos_half = (halfway * normals).sum(dim=1).clamp_min(1e-6)

    def masking(cosine: torch.Tensor) -> torch.Tensor:
        tan2 = (1.0 - cosine**2).clamp_min(0.0) / cosine.clamp_min(1e-6) ** 2
        return 2.0 / (1.0 + (1.0 + alpha**2 * tan2).sqrt())

    weight = masking(cos_view) * masking(cos_light.clamp_min(0.0)) * view_h / (cos_view * cos_half)
    return torch.where(cos_light > 0, weight.clamp(0.0, 1.0), 0.0)


def _footprint(t: torch.Tensor, directions: torch.Tensor, facing: torch.Tensor, pixel_angle: float) -> torch.Tensor:
    """(N,) float32 width of a pixel's footprint on the surfaces that rays (N, 3) meet at ``t`` (N,)
    (in direction lengths), with :meth:`~kadv.render.surface.Surfaces.facing` ``facing`` (N,): the
    geometric mean of its two axes, one stretched by 1 / cos incidence."""
    length = directions.norm(dim=1)
    incidence = facing.abs() / length
    return (t * length * pixel_angle / incidence.clamp_min(0.05).sqrt()).float()


def compact_rows(mask: torch.Tensor) -> torch.Tensor | None:
    """The indices (M,) where ``mask`` (N,) holds, on devices that work on those rows only; None on
    the others (a GPU), which work on every row, masked, sooner than they wait for a count."""
    return torch.nonzero(mask)[:, 0] if mask.device.type in _COMPACTING else None


def _on_rows(
    mask: torch.Tensor,
    compute: Callable[[Callable[[torch.Tensor], torch.Tensor], torch.Tensor | None], torch.Tensor],
    channels: int = 3,
    dtype: torch.dtype = torch.float64,
) -> torch.Tensor:
    """(N, C) ``dtype``: what ``compute(take, live)`` returns (M, ``channels``) for the rows where
    ``mask`` (N,) holds, 0 elsewhere. ``take`` gives the rows of an (N, ...) tensor that ``compute`` works on;
    ``live`` is ``mask`` where those are every row (a GPU's, :func:`compact_rows`), else None."""
    rows = compact_rows(mask)
    if rows is None:
        return torch.where(mask[:, None], compute(lambda values: values, mask), 0.0)
    out = torch.zeros(len(mask), channels, dtype=dtype, device=mask.device)
    if not len(rows):
        return out
    return out.index_copy(0, rows, compute(lambda values: values.index_select(0, rows), None))


def _every_other(images: tuple[int, int, int], device: torch.device) -> torch.Tensor:
    """(N,) True at the pixels of (B, H, W) ``images`` in even rows and even columns."""
    batch, height, width = images
    rows = torch.arange(height, device=device) % 2 == 0
    columns = torch.arange(width, device=device) % 2 == 0
    return (rows[:, None] & columns[None, :]).expand(batch, -1, -1).reshape(-1)


def _smoothed(
    light: torch.Tensor,
    weights: torch.Tensor,
    group: torch.Tensor,
    axis: torch.Tensor,
    images: tuple[int, int, int],
    sigma: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``light`` (N, 3) of the (B, H, W) ``images``' pixels averaged over a Gaussian of ``sigma``
    pixels among the pixels where ``weights`` (N,) bool holds and whose normals point along the
    same ``axis`` (N,), by normalised convolution, at the pixels where ``group`` (N,) holds (0
    elsewhere); and (N,) whether any such pixel is within reach."""
    # the light is summed into cells `step` pixels wide, blurred there and read back bilinearly:
    # work on the whole image only on cells, on pixels only where they feed or read the average
    step = max(1, int(sigma // 2))
    sigma = sigma / step
    size = 2 * math.ceil(2.0 * sigma) + 1
    batch, height, width = images
    cell_rows, cell_columns = -(-height // step), -(-width // step)

    def pixel(rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return rows // (height * width), rows // width % height, rows % width

    def rows_of(mask: torch.Tensor) -> torch.Tensor:
        rows = compact_rows(mask)
        return torch.arange(len(mask), device=mask.device) if rows is None else rows

    feeding = rows_of(weights)
    b, y, x = pixel(feeding)
    cells = ((b * cell_rows + y // step) * cell_columns + x // step) * 3 + axis.index_select(0, feeding)
    fed = torch.cat([light.index_select(0, feeding), light.new_ones(len(feeding), 1)], dim=1).float()
    fed = fed * weights.index_select(0, feeding)[:, None]
    sums = light.new_zeros(batch * cell_rows * cell_columns * 3, 4, dtype=torch.float32).index_add_(0, cells, fed)
    grid = sums.reshape(batch, cell_rows, cell_columns, 12).permute(0, 3, 1, 2)
    blurred = gaussian_blur2d(grid, (size, size), (sigma, sigma), border_type="constant")
    table = blurred.permute(0, 2, 3, 1).reshape(-1, 4)

    def read(take: Callable[[torch.Tensor], torch.Tensor], _: torch.Tensor | None) -> torch.Tensor:
        """(M, 4) the blurred sums at the rows ``take`` gives, between the four nearest cell centres."""
        b, y, x = pixel(take(torch.arange(len(group), device=group.device)))
        a = take(axis)

        def between(at: torch.Tensor, cells: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
            centre = ((at + 0.5) / step - 0.5).clamp(0.0, cells - 1)
            low = centre.floor()
            return low.long(), (low.long() + 1).clamp_max(cells - 1), (centre - low).float()[:, None]

        (y0, y1, fy), (x0, x1, fx) = between(y, cell_rows), between(x, cell_columns)

        def tap(row: torch.Tensor, column: torch.Tensor) -> torch.Tensor:
            return table.index_select(0, ((b * cell_rows + row) * cell_columns + column) * 3 + a)

        upper, lower = torch.lerp(tap(y0, x0), tap(y0, x1), fx), torch.lerp(tap(y1, x0), tap(y1, x1), fx)
        return torch.lerp(upper, lower, fy).double()

    mine = _on_rows(group, read, 4)
    return mine[:, :3] / mine[:, 3:].clamp_min(1e-6), mine[:, 3] > 1e-6


class Reflections(NamedTuple):
    """What coats and metals mirror into a render's pixels (:meth:`Shader.reflections`): where
    ``glossy`` (N,) holds, a pixel's rays on its centre ray's surface show the exposed radiance
    ``kept + factor * mirrored`` in place of their shaded colour, with ``mirrored`` (N, 3) float32
    and their own ``kept`` and ``factor`` (:meth:`Shader.shade`'s "reflecting")."""

    glossy: torch.Tensor
    mirrored: torch.Tensor


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
        self.reflecting = False
        # each triangle's mirror flag and tint, where the scene has mirrors
        self._mirror_flag = self._mirror_tint = None
        if any(material.mirror for material in scene.materials):
            triangles = torch.from_numpy(scene.material_ids).long()
            flags = torch.tensor([material.mirror for material in scene.materials])
            tints = torch.from_numpy(np.stack([material.base_color for material in scene.materials]))
            self._mirror_flag, self._mirror_tint = flags[triangles].to(device), tints[triangles].float().to(device)
        if shading.lighting == "scanned" and scene.colors is None and all(m.texture is None for m in scene.materials):
            raise ValueError(
                f"render.lighting=scanned: scene {scene.name!r} has no vertex colours and no textures, no captured "
                "colour to show; shade it with render.lighting=baked or direct"
            )
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
            # each rough material's smoothing width, and its index in the scene's widths (-1: sharp)
            widths = [_smoothing_width(material.roughness) for material in scene.materials]
            self._widths = sorted({width for width in widths if width is not None})
            self._width_index = per_triangle([-1 if w is None else self._widths.index(w) for w in widths]).long()
            self.reflecting = shading.reflections and bool(((self._coat_ior > 0) | self._conductor).any())
            if self.reflecting and self._emitter_caster is not None:  # an emitter's colour, then its radiance
                self._emitter_table = torch.cat([self._emitter_colour, self._emitter_radiance.float()], dim=1)

    def shade(
        self,
        hits: RayHits,
        origins: torch.Tensor,
        directions: torch.Tensor,
        pixel_angle: float,
        colour: bool = True,
        geometry: bool = True,
        normals: bool = True,
        bounces: int = MIRROR_BOUNCES,
    ) -> dict[str, torch.Tensor]:
        """Shade hits of rays (N, 3) float64 on the surfaces' device; ``pixel_angle`` (radians per
        sample) selects the texture mip level. A mirror's colour is what its specular bounce meets,
        shaded the same way and tinted by its base colour, for at most ``bounces`` bounces (then its
        own shading).

        Returns "rgb" (N, 3) float32 and, with ``geometry``, the masked "points", "normals" (N, 3)
        float32 (with ``normals``: interpolating them is most of a bare cast's shading) and
        "back_face" (N,) bool, on the same device. With ``colour`` False "rgb" is the
        background: the caller takes colour from other rays. With ``colour`` when coats and metals
        reflect (:attr:`reflecting`), also "reflecting" (N, 6) float32: on their hits, the exposed
        radiance each keeps besides its mirror image and the factor of the mirrored light
        (what :meth:`reflections` adds to).
        """
        # Every ray is shaded (a miss as a point on triangle 0 at the eye) and misses are masked at
        # the end: indoors nearly every ray hits, and compacting the hits would cost more (and, on a
        # GPU, a wait for their count).
        hit, ids, bary = hits.hit, hits.triangle_ids.clamp_min(0), hits.barycentrics
        t = torch.where(hit, hits.t.double(), 0.0)
        facing = self.surfaces.facing(ids, directions)
        back = hit & (facing > 0)
        # hit points and shading normals, where something reads them: the maps, Lambert's term or
        # the delta lights (baked light alone needs neither)
        lit_at_points = self.shading.lighting == "direct" or (self.baked is not None and not self._delta_lights.empty)
        points = shading_normals = terms = None
        if geometry or (colour and lit_at_points):
            points = origins + directions * t[:, None]
        if (geometry and normals) or (colour and lit_at_points):
            shading_normals = self._shading_normals(ids, bary, back, directions)
        rgb = self._background.expand(len(t), 3)
        if colour:
            footprint = _footprint(t, directions, facing, pixel_angle)
            shaded, background, terms = self._lit(hits, footprint, back, points, directions, shading_normals)
            rgb = torch.where(hit[:, None], shaded, background)
            if self._emitter_caster is not None:
                rgb, terms = self._lamps_seen(hits, origins, directions, rgb, terms)
            if bounces > 0 and self._mirror_flag is not None:
                rgb = self._through_mirrors(hits, origins, directions, rgb, pixel_angle, bounces)
        maps = {"rgb": rgb.contiguous()}
        if colour and self.reflecting:
            maps["reflecting"] = terms
        if geometry:
            maps.update(points=torch.where(hit[:, None], points.float(), 0.0), back_face=back)
        if geometry and normals:
            maps["normals"] = torch.where(hit[:, None], shading_normals, 0.0)
        return maps

    def _lit(
        self,
        hits: RayHits,
        footprint: torch.Tensor,
        back: torch.Tensor,
        points: torch.Tensor | None,
        directions: torch.Tensor,
        shading_normals: torch.Tensor | None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Each hit's colour (N, 3) under the lighting, the background, and (baked, where coats and
        metals reflect) :meth:`shade`'s "reflecting" terms."""
        ids, bary = hits.triangle_ids.clamp_min(0), hits.barycentrics
        if self.shading.lighting == "scanned":
            return self.surfaces.captured(ids, bary, footprint), self._background, None
        if self.baked is None:
            base = self.surfaces.albedo(ids, bary, footprint)
            return shade(self.shading, self._lights, points.float(), shading_normals, base), self._background, None
        return self._baked_colours(hits, bary, footprint, back, points, directions, shading_normals)

    def _through_mirrors(
        self,
        hits: RayHits,
        origins: torch.Tensor,
        directions: torch.Tensor,
        rgb: torch.Tensor,
        pixel_angle: float,
        bounces: int,
    ) -> torch.Tensor:
        """``rgb`` (N, 3) with each mirror hit's colour replaced by its reflection's."""
        ids = hits.triangle_ids.clamp_min(0)
        rows = torch.nonzero(hits.hit & self._mirror_flag.index_select(0, ids)).squeeze(1)
        if len(rows) == 0:
            return rgb
        mirror_ids, ray = ids.index_select(0, rows), directions.index_select(0, rows)
        normal = self.surfaces.face_normals.index_select(0, mirror_ids)
        normal = torch.where((dot(normal, ray) > 0)[:, None], -normal, normal)  # towards the eye
        point = origins.index_select(0, rows) + ray * hits.t.double().index_select(0, rows)[:, None]
        reflected = ray - 2.0 * dot(ray, normal)[:, None] * normal
        start = point + SURFACE_OFFSET * normal
        seen = self.surfaces.cast(start, reflected)
        colours = self.shade(seen, start, reflected, pixel_angle, geometry=False, bounces=bounces - 1)["rgb"]
        return rgb.index_copy(0, rows, colours * self._mirror_tint.index_select(0, mirror_ids))

    def _shading_normals(
        self, ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor, directions: torch.Tensor
    ) -> torch.Tensor:
        """The hits' unit shading normals (N, 3), turned to the eye's side: by the side hit, or, for
        a scan, whose winding is random, by their own side."""
        normals = F.normalize(self.surfaces.interpolate(self.surfaces.normals, ids, bary), dim=1, eps=1e-12)
        away = back if self.shading.lighting != "scanned" else (normals * directions).sum(dim=1) > 0
        return torch.where(away[:, None], -normals, normals)

    def _lamps_seen(
        self, hits: RayHits, origins: torch.Tensor, directions: torch.Tensor, rgb: torch.Tensor, terms
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The colours (N, 3) and reflection terms with the glow of the emitters the rays see in
        front of what they hit: a lamp in front of a coat shows its glow, nothing mirrored."""
        table = self._emitter_table if self.reflecting else self._emitter_colour
        seen, glow = self._emitter_glow(hits, origins, directions, table)
        rgb = torch.where(seen[:, None], glow[:, :3], rgb)
        if self.reflecting:
            terms = torch.where(seen[:, None], F.pad(glow[:, 3:], (0, 3)), terms)
        return rgb, terms

    def _baked_colours(
        self, hits: RayHits, bary: torch.Tensor, footprint: torch.Tensor, back: torch.Tensor,
        points: torch.Tensor | None, directions: torch.Tensor, normals: torch.Tensor | None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:  # fmt: skip
        """Under baked light: the hits' tone-mapped colours (N, 3), the sky each ray sees where it
        leaves the scene (the light the bake was lit by), and, where coats and metals reflect, their
        reflection terms (:meth:`shade`'s "reflecting"; else None)."""
        hit, ids = hits.hit, hits.triangle_ids.clamp_min(0)
        base = self.surfaces.albedo(ids, bary, footprint)
        # the lattice weights in float64: a hit's place between lattice points is a small difference
        irradiance = self.baked.irradiance_at(ids, bary.double(), back)
        if not self._delta_lights.empty:
            irradiance = irradiance + self._delta_irradiance(points, directions, normals, hit)
        radiance = self.surfaces.reflectance(ids, base) * irradiance * (self.baked.exposure / math.pi)
        terms = self._reflecting_terms(hit, ids, base, radiance, irradiance) if self.reflecting else None
        sky = self._sky(F.normalize(directions, dim=1))
        return tone_map(radiance), tone_map((sky * self.baked.exposure).float()), terms

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

    def _emitter_in_front(
        self, hits: RayHits, origins: torch.Tensor, directions: torch.Tensor, where: torch.Tensor
    ) -> torch.Tensor:
        """(N,) True where rays (N, 3) with ``where`` (N,) meet an area emitter before ``hits``."""
        rows = compact_rows(where)
        if rows is None:
            return where & self._emitter_glow(hits, origins, directions, self._emitter_colour)[0]
        part = RayHits(*(values.index_select(0, rows) for values in (hits.t, hits.triangle_ids, hits.barycentrics)))
        seen = self._emitter_glow(
            part, origins.index_select(0, rows), directions.index_select(0, rows), self._emitter_colour
        )[0]
        return torch.zeros_like(where).index_put((rows,), seen)

    def reflections(
        self,
        hits: RayHits,
        normals: torch.Tensor,
        origins: torch.Tensor,
        directions: torch.Tensor,
        pixel_angle: float,
        images: tuple[int, int, int],
    ) -> Reflections:
        """What coats and metals mirror, for :attr:`Shading.reflections`, at the pixels whose centre
        rays (N, 3) met one (:class:`Reflections`), with the hits' shading ``normals`` (N, 3) turned
        towards the eye (:meth:`shade`'s "normals"): what one ray per pixel, drawn from the GGX lobe,
        meets in baked light (the sky, an emitter's glow, a surface's diffuse light without its
        point lights and suns), weighted by the lobe and the coat's Fresnel reflectance (a metal's
        is 1). It takes the place of the coat's reflection that the shading counted diffuse, or of
        a metal's diffuse look (:meth:`shade`'s "reflecting").

        The rows are the (B, H, W) ``images``' pixels in order. A lobe rougher than
        :data:`SHARP_ROUGHNESS` would sparkle with one ray per pixel: its mirrored light is averaged
        over a Gaussian of half its GGX alpha in radians (at least ``_REFLECTION_SMOOTHING``) among
        the pixels of its roughness whose normals point along the same axis (normalised
        convolution): a stair's treads apart from its risers.
        """
        ids = hits.triangle_ids.clamp_min(0)
        glossy = hits.hit & ((self._coat_ior.index_select(0, ids) > 0) | self._conductor.index_select(0, ids))
        if self._emitter_caster is not None:  # a lamp in front of the surface shows its own glow
            glossy = glossy & ~self._emitter_in_front(hits, origins, directions, glossy)
        width_index = self._width_index.index_select(0, ids)
        rough = glossy & (width_index >= 0)
        # the averages span several pixels: a ray at every other pixel along each axis feeds them
        wide = _REFLECTION_SMOOTHING / pixel_angle >= 2.0
        casting = glossy & (~rough | _every_other(images, hits.hit.device)) if wide else glossy
        mirrored = self._mirrored(hits, normals, origins, directions, casting, pixel_angle)
        # the axis along which each normal points most
        axes, covered = normals.abs().argmax(dim=1), torch.zeros_like(rough)
        for index, width in enumerate(self._widths):
            group = rough & (width_index == index)
            smoothed, reached = _smoothed(mirrored, group & casting, group, axes, images, width / pixel_angle)
            mirrored = torch.where(group[:, None], smoothed, mirrored)
            covered = covered | (group & reached)
        glossy = glossy & (~rough | covered)
        return Reflections(glossy, mirrored.float())

    def _reflecting_terms(
        self, hit: torch.Tensor, ids: torch.Tensor, base: torch.Tensor, radiance: torch.Tensor, irradiance: torch.Tensor
    ) -> torch.Tensor:
        """(N, 6) float32 :meth:`shade`'s "reflecting" for hits (N,) on triangles (N,) of display
        colour ``base`` (N, 3), shaded to the exposed ``radiance`` (N, 3) from ``irradiance`` (N,
        3): on a coat, its radiance less the coat's own reflection (which the shading counted
        diffuse) and a factor 1 on the mirrored light; on a metal, no radiance and its reflectance
        (its display albedo over :data:`~kadv.scenes.scene.CONDUCTOR_GREY`); 0 elsewhere."""
        glossy = hit & ((self._coat_ior.index_select(0, ids) > 0) | self._conductor.index_select(0, ids))

        def terms(take: Callable[[torch.Tensor], torch.Tensor], _: torch.Tensor | None) -> torch.Tensor:
            rows = take(ids)
            own = self.surfaces.coats.index_select(0, rows)[:, 2:3] * take(irradiance)
            coat = torch.cat([take(radiance) - own * (self.baked.exposure / math.pi), torch.ones_like(own)], dim=1)
            reflectance = srgb_decode((take(base) / CONDUCTOR_GREY).clamp(0.0, 1.0))
            metal = torch.cat([torch.zeros_like(reflectance), reflectance], dim=1)
            return torch.where(self._conductor.index_select(0, rows)[:, None], metal, coat)

        return _on_rows(glossy, terms, 6, torch.float32)

    def _mirrored(
        self,
        hits: RayHits,
        normals: torch.Tensor,
        origins: torch.Tensor,
        directions: torch.Tensor,
        casting: torch.Tensor,
        pixel_angle: float,
    ) -> torch.Tensor:
        """(N, 3) float64 exposed radiance that one ray drawn from the GGX lobe of each hit where
        ``casting`` (N,) holds brings towards the eye, weighted by the lobe and the coat's Fresnel
        reflectance (a metal's is 1); 0 elsewhere."""
        return _on_rows(
            casting, lambda take, live: self._mirror(take, live, hits, normals, origins, directions, pixel_angle)
        )

    def _mirror(
        self,
        take: Callable[[torch.Tensor], torch.Tensor],
        live: torch.Tensor | None,
        hits: RayHits,
        normals: torch.Tensor,
        origins: torch.Tensor,
        directions: torch.Tensor,
        pixel_angle: float,
    ) -> torch.Tensor:
        """(M, 3) :meth:`_mirrored`'s light of the rows ``take`` gives; ``live``: the rays to cast
        among them (None: all)."""
        ids, view = take(hits.triangle_ids.clamp_min(0)), F.normalize(take(directions), dim=1)
        normal = take(normals).double()
        roughness = self._roughness.index_select(0, ids)
        halfway = _ggx_half_vectors(normal, roughness, _lobe_samples(view))
        view_h = (-(view * halfway).sum(dim=1)).clamp_min(0.0)
        reflected = view + 2.0 * view_h[:, None] * halfway
        weight = _ggx_weight(view, normal, halfway, view_h, reflected, roughness)
        is_metal = self._conductor.index_select(0, ids)
        # a metal's Fresnel term is taken as 1: its colour comes from its reflectance
        ior = torch.where(is_metal, 1.5, self._coat_ior.index_select(0, ids))
        weight = weight * torch.where(is_metal, 1.0, fresnel_reflectance(view_h, ior))
        distance = take(torch.where(hits.hit, hits.t.double(), 0.0)) * take(directions).norm(dim=1)
        start = take(origins) + view * distance[:, None] + SURFACE_OFFSET * normal
        seen = self.surfaces.cast(start, reflected, live)
        met = seen.hit
        met_ids = seen.triangle_ids.clamp_min(0)
        met_back = met & (self.surfaces.facing(met_ids, reflected) > 0)
        # the texture filtered to the reflection's footprint: the eye's distance plus the mirror's
        footprint = (distance + torch.where(met, seen.t.double(), 0.0)) * pixel_angle
        met_base = self.surfaces.albedo(met_ids, seen.barycentrics, footprint.float())
        light = self.baked.irradiance_at(met_ids, seen.barycentrics.double(), met_back)
        surface = self.surfaces.reflectance(met_ids, met_base) * light * (self.baked.exposure / math.pi)
        incoming = torch.where(met[:, None], surface.double(), self._sky(reflected) * self.baked.exposure)
        if self._emitter_caster is not None:
            glowing, glow = self._emitter_glow(seen, start, reflected, self._emitter_radiance)
            incoming = torch.where(glowing[:, None], glow, incoming)
        return weight[:, None] * incoming

    def same_surface(self, triangle_ids: torch.Tensor, others: torch.Tensor) -> torch.Tensor:
        """(N,) True where hits on triangles (N,) and ``others`` (N,) (-1: a miss) show one surface
        to a reflection: the same material, face normals within 45 degrees (a curved rail's
        triangles are one surface; a stair's tread and riser are two)."""
        a, b = triangle_ids.clamp_min(0), others.clamp_min(0)
        material = self.surfaces.materials.material_ids
        cosine = dot(self.surfaces.face_normals.index_select(0, a), self.surfaces.face_normals.index_select(0, b))
        same = material.index_select(0, a) == material.index_select(0, b)
        return (triangle_ids >= 0) & (others >= 0) & same & (cosine.abs() > math.sqrt(0.5))
