"""Exact renderer: ray casting (Open3D's Embree or Warp's BVH, :mod:`kadv.render.casting`) with
view-independent shading.

All cameras of a call are cast in one batch against one caster built per scene. Values are exact
and bit-identical across runs; nothing here carries a gradient.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import torch
from torch.nn import functional as F

from kadv.checks import check_shape
from kadv.geometry.camera import pixel_rays
from kadv.geometry.vector import dot
from kadv.render.casting import RayCaster, make_caster
from kadv.render.lighting import (
    BakedLighting,
    coat_table,
    coated_albedo,
    delta_irradiance,
    load_or_bake,
    sky_emitters,
    sky_radiance,
    srgb_decode,
    tone_map,
)
from kadv.render.shading import Shading, albedo, mip_pyramid, sample_texture, scene_lights, shade, uv_density
from kadv.scenes.scene import Scene

__all__ = ["ExactRenderer", "RayHits", "RenderOutput", "pixel_angle"]

_ALPHA_CUTOFF = 0.5
_MIN_HIT_DEPTH = 1e-6  # metres


@dataclass
class RenderOutput:
    """What one exact render returns (B cameras, H x W pixels).

    Attributes:
        rgb: (B, 3, H, W) float32 in [0, 1].
        depth: (B, 1, H, W) float32 z-depth in metres, 0 where invalid.
        mask: (B, 1, H, W) bool, True where a ray hit a surface (beyond a micrometre of the eye).
        normals: (B, 3, H, W) float32 world-frame unit normals facing the camera side, 0 if invalid.
        triangle_ids: (B, 1, H, W) int64, -1 where invalid.
        points: (B, 3, H, W) float32 world-frame hit points, 0 where invalid.
        back_face: (B, 1, H, W) bool, True where the ray hit the back of a triangle.
    """

    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor
    normals: torch.Tensor
    triangle_ids: torch.Tensor
    points: torch.Tensor
    back_face: torch.Tensor

    def to(self, device: torch.device | str) -> RenderOutput:
        """The same maps on ``device``."""
        return RenderOutput(**{f.name: getattr(self, f.name).to(device) for f in fields(self)})

    def cropped(self, border: int) -> RenderOutput:
        """The same maps without ``border`` pixels on each side."""
        inner = (..., slice(border, -border), slice(border, -border))
        return RenderOutput(**{f.name: getattr(self, f.name)[inner] for f in fields(self)})


@dataclass
class RayHits:
    """Hits of N rays: parameter t (z-depth for z=1 directions), triangle id (-1 = miss), barycentrics."""

    t: np.ndarray
    triangle_ids: np.ndarray
    barycentrics: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.triangle_ids >= 0


def _cast(caster: RayCaster, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hits of rays (N, 3): t (inf on a miss), triangle id (-1 on a miss) and barycentrics."""
    t, ids, bary = caster.first_hits(*_rays(caster, origins, directions))
    return t.cpu().numpy().astype(np.float64), ids.cpu().numpy(), bary.cpu().numpy().astype(np.float64)


def _rays(caster: RayCaster, *arrays: np.ndarray) -> list[torch.Tensor]:
    """float32 tensors on the caster's device of arrays (N, 3)."""
    return [torch.from_numpy(np.asarray(a, np.float32).reshape(-1, 3)).to(caster.device) for a in arrays]


def pixel_angle(K: torch.Tensor) -> float:
    """Angle in radians one pixel subtends at the image centre (the smallest of the batch)."""
    K = torch.as_tensor(K, dtype=torch.float64).reshape(-1, 3, 3)
    return float(1.0 / torch.maximum(K[:, 0, 0], K[:, 1, 1]).max())


class ExactRenderer:
    """Ray-cast renderer of a :class:`Scene`.

    Args:
        scene: the scene; its triangles go into one ray caster reused by every call.
        shading: shading parameters; with ``lighting="baked"`` the scene's lighting is read from the
            bake cache, or baked there first.
        progress: show the bake's progress bar.
        backend: the ray caster: ``"open3d"`` (Embree, CPU), ``"warp"`` (Warp's BVH on ``device``)
            or ``"auto"`` (Warp on CUDA, Open3D on the CPU).
        device: where the rays are cast.
    """

    def __init__(
        self,
        scene: Scene,
        shading: Shading | None = None,
        progress: bool = True,
        backend: str = "auto",
        device: torch.device | str = "cpu",
    ) -> None:
        self.scene = scene
        self.shading = shading or Shading()
        self.lights = scene_lights(scene, self.shading)

        def caster(vertices: np.ndarray, faces: np.ndarray) -> RayCaster:
            return make_caster(vertices, faces, backend, device)

        self.caster = caster(scene.vertices, scene.faces)
        # A ray that met a transparent texel continues in two smaller scenes: the first hit among the
        # opaque materials' triangles, and every hit on the alpha-masked ones (a few, where listing
        # them in the whole scene would list every wall behind).
        masked_faces = np.array([m.opacity is not None for m in scene.materials], bool)[scene.material_ids]
        self._masked_face = np.r_[masked_faces, False]  # per triangle, and a False that a miss (id -1) reads
        self._opaque_faces, self._masked_faces = np.flatnonzero(~masked_faces), np.flatnonzero(masked_faces)
        if len(self._masked_faces):
            self._opaque_caster = caster(scene.vertices, scene.faces[self._opaque_faces])
            self._masked_caster = caster(scene.vertices, scene.faces[self._masked_faces])
        # shading reads these per hit: torch copies made once
        self._pyramids = {i: mip_pyramid(m.texture) for i, m in enumerate(scene.materials) if m.texture is not None}
        self._opacity = {
            i: torch.from_numpy(np.ascontiguousarray(m.opacity[:, :, None], np.float32))
            for i, m in enumerate(scene.materials)
            if m.opacity is not None
        }
        self._uv_density = torch.from_numpy(uv_density(scene).astype(np.float32))
        self._uvs = torch.from_numpy(scene.uvs.astype(np.float64))
        self._normals = torch.from_numpy(scene.normals.astype(np.float32))
        self._face_normals = torch.from_numpy(scene.face_normals.astype(np.float64))
        self._lights = torch.from_numpy(self.lights.astype(np.float32))
        self.baked: BakedLighting | None = None
        self._emitter_caster = None
        self._coats = torch.from_numpy(coat_table(scene)).float()[torch.from_numpy(scene.material_ids)]
        if self.shading.lighting == "baked":
            self.baked = load_or_bake(self, self.shading.bake, progress)
            self._delta_lights = bool(len(scene.emitters.point_positions) or len(scene.emitters.sun_directions))
            self._sky = sky_emitters(scene)
            emitters = scene.emitters.area_triangles
            if len(emitters):  # the file's lamps and glowing panels, seen as a camera sees them
                self._emitter_caster = caster(emitters.reshape(-1, 3), np.arange(3 * len(emitters)).reshape(-1, 3))
                cross = np.cross(emitters[:, 1] - emitters[:, 0], emitters[:, 2] - emitters[:, 0])
                self._emitter_normals = torch.from_numpy(cross)
                self._emitter_colour = tone_map(
                    torch.from_numpy(scene.emitters.area_radiance * self.baked.exposure)
                ).float()

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """Cast rays (..., 3) each; alpha-masked texels let rays through.

        Returns:
            Hits flattened to N = prod(...) rays.
        """
        origins = origins.reshape(-1, 3)
        directions = directions.reshape(-1, 3)
        t, ids, bary = _cast(self.caster, origins, directions)
        if len(self._masked_faces):
            # the few rays that met a transparent texel take their first opaque hit from one cast and
            # one list of intersections, however many leaves they pass
            pending = np.flatnonzero(self.see_through(ids, bary))
            if len(pending):
                t[pending], ids[pending], bary[pending] = self._first_opaque(origins[pending], directions[pending])
        return RayHits(t, ids, bary)

    def _first_opaque(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First opaque hit (t, triangle id, barycentrics) of rays (N, 3) whose first hit is a
        transparent texel: the nearer of the first hit on an opaque material's triangle and the
        first opaque texel among the hits on alpha-masked triangles."""
        t, local, bary = _cast(self._opaque_caster, origins, directions)
        ids = np.where(local >= 0, self._opaque_faces[np.maximum(local, 0)], -1)
        ray_ids, t_masked, ids_masked, bary_masked = self._list_opaque(
            self._masked_caster, self._masked_faces, origins, directions
        )
        first = np.r_[True, ray_ids[1:] != ray_ids[:-1]] if len(ray_ids) else np.zeros(0, bool)
        nearer = first & (t_masked < t[ray_ids])
        rays = ray_ids[nearer]
        t[rays], ids[rays], bary[rays] = t_masked[nearer], ids_masked[nearer], bary_masked[nearer]
        return t, ids, bary

    def intersections(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, ...]:
        """Every opaque intersection of rays (N, 3), sorted by ray then distance: ray index (M,),
        parameter t (M,), triangle id (M,) and barycentrics (M, 2)."""
        return self._list_opaque(self.caster, None, origins, directions)

    def _list_opaque(
        self, caster: RayCaster, faces: np.ndarray | None, origins: np.ndarray, directions: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        """:meth:`intersections` in ``caster``, whose triangle i is the scene's ``faces[i]`` (or i
        when ``faces`` is None)."""
        ray_ids, t, ids, bary = (x.cpu().numpy() for x in caster.all_hits(*_rays(caster, origins, directions)))
        t, bary = t.astype(np.float64), bary.astype(np.float64)
        ids = ids if faces is None else faces[ids]
        if len(t):
            opaque = ~self.see_through(ids, bary)
            ray_ids, t, ids, bary = ray_ids[opaque], t[opaque], ids[opaque], bary[opaque]
        order = np.lexsort((t, ray_ids))
        return ray_ids[order], t[order], ids[order], bary[order]

    def see_through(self, ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(N,) True where a hit (triangle ids, barycentrics) falls on a transparent texel of an alpha mask."""
        see_through = np.zeros(len(ids), bool)
        candidates = np.flatnonzero(self._masked_face[ids])
        material_ids = self.scene.material_ids[ids[candidates]]
        for index in np.unique(material_ids):
            selected = candidates[material_ids == index]
            uv = self._interpolate(self._uvs, torch.from_numpy(ids[selected]), torch.from_numpy(bary[selected]))
            uv_scale = torch.as_tensor(self.scene.materials[index].uv_scale, dtype=uv.dtype)
            alpha = sample_texture(self._opacity[index], uv * uv_scale)[:, 0]
            see_through[selected[(alpha < _ALPHA_CUTOFF).numpy()]] = True
        return see_through

    def back_facing(self, hits: RayHits, directions: np.ndarray) -> np.ndarray:
        """(N,) True where a ray (directions (..., 3), N in all) hit the back of a triangle; False on misses."""
        # a copy: the directions may be a read-only broadcast view
        facing = self._facing(
            torch.from_numpy(np.maximum(hits.triangle_ids, 0)),
            torch.tensor(directions.reshape(-1, 3), dtype=torch.float64),
        )
        return hits.hit & (facing > 0).numpy()

    def _facing(self, triangle_ids: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        """(N,) dot products of ray directions (N, 3) with their triangles' face normals: positive
        where a ray meets the back of its triangle."""
        return dot(self._face_normals.index_select(0, triangle_ids), directions)

    @staticmethod
    def _interpolate(per_corner: torch.Tensor, triangle_ids: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """Interpolate per-corner attributes (F, 3, C) at barycentrics (N, 2) (Open3D's (u, v)), in
        the attributes' dtype."""
        bary = bary.to(per_corner.dtype)
        corners = per_corner.flatten(1).index_select(0, triangle_ids).reshape(-1, *per_corner.shape[1:])
        return (
            corners[:, 0] * (1.0 - bary[:, 0:1] - bary[:, 1:2])
            + corners[:, 1] * bary[:, 0:1]
            + corners[:, 2] * bary[:, 1:2]
        )

    def reflectance(self, triangle_ids: torch.Tensor, base: torch.Tensor) -> torch.Tensor:
        """(N, 3) linear albedo that baked lighting multiplies: of the display colours ``base``
        (N, 3) on triangles (N,), with their materials' coats (:func:`coated_albedo`)."""
        return coated_albedo(srgb_decode(base), self._coats.index_select(0, triangle_ids))

    def shade_hits(
        self,
        hits: RayHits,
        origins: np.ndarray,
        directions: np.ndarray,
        pixel_angle: float,
        colour: bool = True,
        geometry: bool = True,
    ) -> dict[str, np.ndarray]:
        """Shade hits; ``pixel_angle`` (radians per sample) selects the texture mip level.

        Returns "rgb" (N, 3) float32 and, with ``geometry``, the masked "points", "normals" (N, 3)
        and "back_face" (N,). With ``colour`` False "rgb" is the background: the caller takes
        colour from other rays.
        """
        # Every ray is shaded (a miss as a point on triangle 0 at the eye) and misses are masked at
        # the end: indoors nearly every ray hits, and compacting the hits would cost more.
        hit = torch.from_numpy(hits.hit)
        ids = torch.from_numpy(np.maximum(hits.triangle_ids, 0))
        bary = torch.from_numpy(hits.barycentrics)
        t = torch.from_numpy(np.where(hits.hit, hits.t, 0.0))
        dirs = torch.from_numpy(directions.reshape(-1, 3))
        points = (torch.from_numpy(origins.reshape(-1, 3)) + dirs * t[:, None]).float()
        facing = self._facing(ids, dirs)
        back = hit & (facing > 0)
        normals = F.normalize(self._interpolate(self._normals, ids, bary), dim=1, eps=1e-12)
        normals = torch.where(back[:, None], -normals, normals)
        background = torch.tensor(self.shading.background, dtype=torch.float32)
        rgb = background.expand(len(t), 3)
        if colour:
            uv = self._interpolate(self._uvs, ids, bary)
            length = dirs.norm(dim=1)
            incidence = facing.abs() / length
            # geometric mean of the footprint's two axes (one stretched by 1 / cos incidence)
            footprint = t * length * pixel_angle / incidence.clamp_min(0.05).sqrt()
            base = albedo(self.scene, ids, uv, footprint.float(), self._pyramids, self._uv_density)
            if self.baked is None:
                shaded = shade(self.shading, self._lights, points, normals, base)
            else:
                irradiance = self.baked.irradiance_at(ids, bary, back)
                if self._delta_lights:
                    irradiance = irradiance + self._delta_irradiance(hits, origins, directions, normals)
                shaded = tone_map(self.reflectance(ids, base) * irradiance * (self.baked.exposure / math.pi))
                # a ray that leaves the scene sees the sky the bake was lit by
                sky = sky_radiance(self._sky, F.normalize(dirs, dim=1).numpy())
                background = tone_map(torch.from_numpy(sky * self.baked.exposure).float())
            rgb = torch.where(hit[:, None], shaded, background)
            if self._emitter_caster is not None:
                rgb = self._emitters_seen(rgb, hits, origins, directions)
        maps = {"rgb": np.ascontiguousarray(rgb.numpy())}
        if geometry:
            maps.update(
                points=torch.where(hit[:, None], points, 0.0).numpy(),
                normals=torch.where(hit[:, None], normals, 0.0).numpy(),
                back_face=back.numpy(),
            )
        return maps

    def _delta_irradiance(
        self, hits: RayHits, origins: np.ndarray, directions: np.ndarray, normals: torch.Tensor
    ) -> torch.Tensor:
        """(N, 3) irradiance at the hits from the scene's point, spot and sun lights, with one
        shadow ray each (zero on misses)."""
        hit = hits.hit
        dirs = directions.reshape(-1, 3)[hit]
        points = origins.reshape(-1, 3)[hit] + dirs * hits.t[hit, None]
        facing = normals.numpy()[hit].astype(np.float64)
        # the side the ray arrived from, whatever the file's normals say
        facing *= np.where(np.einsum("nd,nd->n", facing, dirs) > 0, -1.0, 1.0)[:, None]
        irradiance = torch.zeros(len(hit), 3)
        irradiance[torch.from_numpy(hit)] = torch.from_numpy(
            delta_irradiance(self, self.scene.emitters, points, facing)
        ).float()
        return irradiance

    def _emitters_seen(
        self, rgb: torch.Tensor, hits: RayHits, origins: np.ndarray, directions: np.ndarray
    ) -> torch.Tensor:
        """``rgb`` (N, 3) with the colour of an area emitter wherever a ray meets one before any
        surface: its radiance on its emitting side, black behind. Emitters are no geometry (they
        carry no depth): only the colour shows them."""
        t, ids, _ = _cast(self._emitter_caster, origins.reshape(-1, 3), directions.reshape(-1, 3))
        seen = torch.from_numpy((ids >= 0) & (t < np.where(hits.hit, hits.t, np.inf)))
        ids = torch.from_numpy(np.maximum(ids, 0))
        facing = dot(self._emitter_normals.index_select(0, ids), torch.from_numpy(directions.reshape(-1, 3))) < 0
        glow = self._emitter_colour.index_select(0, ids) * facing[:, None]
        return torch.where(seen[:, None], glow, rgb)

    def render(
        self,
        world_T_cam: torch.Tensor,
        K: torch.Tensor,
        height: int,
        width: int,
        supersample: int = 1,
        sub_rgb: torch.Tensor | None = None,
    ) -> RenderOutput:
        """Render B cameras in one cast.

        Args:
            world_T_cam: (B, 4, 4) or (4, 4) poses (OpenCV camera, metres).
            K: (3, 3) or (B, 3, 3) intrinsics.
            height: image height.
            width: image width.
            supersample: s; RGB averages s x s rays per pixel, depth and the other maps come from the
                pixel-centre ray.
            sub_rgb: (B, 3, s * height, s * width) colours of those s x s rays, when the caller has
                already shaded them (an anchor render at this pose covers them): they are not cast again.

        Raises:
            ValueError: on a NaN or non-rigid pose, bad intrinsics or a bad size.
        """
        origins, directions = pixel_rays(world_T_cam, K, height, width)
        batch, s = origins.shape[0], supersample
        hits = self.cast(origins, directions)
        angle = pixel_angle(K)
        maps = self.shade_hits(hits, origins, directions, angle, colour=s == 1)

        def image(values: np.ndarray, channels: int) -> torch.Tensor:
            return torch.from_numpy(
                np.ascontiguousarray(values.reshape(batch, height, width, channels).transpose(0, 3, 1, 2))
            )

        if sub_rgb is not None:
            if s == 1:
                raise ValueError("sub_rgb: given with supersample 1, where there are no sub-pixel rays")
            check_shape(sub_rgb, f"B 3 {s * height} {s * width}", "sub_rgb", {"B": batch})
        elif s > 1:
            sub_origins, sub_dirs = pixel_rays(world_T_cam, K, height, width, s)
            sub = self.shade_hits(self.cast(sub_origins, sub_dirs), sub_origins, sub_dirs, angle / s, geometry=False)[
                "rgb"
            ]
            sub_rgb = torch.from_numpy(sub).reshape(batch, s * height, s * width, 3).permute(0, 3, 1, 2)
        rgb = F.avg_pool2d(sub_rgb, s).contiguous() if s > 1 else image(maps["rgb"], 3)

        # a ray that meets a surface within a micrometre of the eye starts on it (the eye lies on the
        # surface): it measures no depth, so it is no hit in the mask
        mask = hits.hit & (hits.t > _MIN_HIT_DEPTH)
        depth = np.where(mask, hits.t, 0.0).astype(np.float32)
        return RenderOutput(
            rgb=rgb,
            depth=image(depth, 1),
            mask=image(mask, 1),
            normals=image(maps["normals"], 3),
            triangle_ids=image(hits.triangle_ids, 1),
            points=image(maps["points"], 3),
            back_face=image(maps["back_face"], 1),
        )
