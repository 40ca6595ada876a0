"""What a ray hit: the scene's triangles behind ray casters of one backend, alpha-masked texels
that let rays through, and per hit its texture coordinates, shading normal, side and albedo.

The renderer (:mod:`kadv.render.exact`), the bake, the layers, the silhouette term and the
validity checks all cast through one :class:`Surfaces`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from kadv.device import free_memory
from kadv.geometry.vector import dot
from kadv.render.backends import make_caster
from kadv.render.casting import AlphaMasks, RayCaster
from kadv.render.colour import coat_table, coated_albedo, srgb_decode, srgb_encode
from kadv.render.textures import MaterialTextures, TextureAtlas
from kadv.scenes.scene import Scene

__all__ = ["RayHits", "Surfaces", "first_hits", "pyramid_bytes"]

_ALPHA_CUTOFF = 0.5


@dataclass
class RayHits:
    """Hits of N rays, tensors on the caster's device.

    Attributes:
        t: (N,) float32 ray parameter (z-depth for z = 1 directions), inf on a miss.
        triangle_ids: (N,) int64, -1 on a miss.
        barycentrics: (N, 2) float32, Open3D's (u, v).
    """

    t: torch.Tensor
    triangle_ids: torch.Tensor
    barycentrics: torch.Tensor

    @property
    def hit(self) -> torch.Tensor:
        return self.triangle_ids >= 0

    def numpy(self) -> RayHits:
        """The same hits as host arrays (t and barycentrics float64), for the stages that still
        compute on the host (the bake, the step guard, the validity probes, the silhouette search)."""
        return RayHits(
            self.t.cpu().double().numpy(), self.triangle_ids.cpu().numpy(), self.barycentrics.cpu().double().numpy()
        )


def _vectors(device: torch.device, dtype: torch.dtype, *arrays: torch.Tensor | np.ndarray) -> list[torch.Tensor]:
    """(N, 3) tensors of ``dtype`` on ``device`` of vectors (..., 3): tensors, or host arrays (copied:
    they may be read-only broadcast views)."""
    return [
        (torch.from_numpy(np.array(a, np.float64)) if isinstance(a, np.ndarray) else a).reshape(-1, 3).to(device, dtype)
        for a in arrays
    ]


def _rays(device: torch.device, *arrays: torch.Tensor | np.ndarray) -> list[torch.Tensor]:
    """float32 (N, 3) tensors on ``device`` of rays (..., 3)."""
    return _vectors(device, torch.float32, *arrays)


def first_hits(
    caster: RayCaster,
    origins: torch.Tensor | np.ndarray,
    directions: torch.Tensor | np.ndarray,
    live: torch.Tensor | None = None,
) -> RayHits:
    """First hits of rays (..., 3) in one caster (alpha masks not applied), flattened; ``live`` (N,):
    the rays to cast, the others misses (None: all)."""
    return RayHits(*caster.first_hits(*_rays(caster.device, origins, directions), live))


def pyramid_bytes(scene: Scene) -> int:
    """Bytes of the scene's texture pyramids (float32 levels, each a quarter of the one before:
    4/3 of the full-size level) and alpha masks."""
    texels = sum(m.texture.size * 4 // 3 for m in scene.materials if m.texture is not None)
    return 4 * (texels + sum(m.opacity.size for m in scene.materials if m.opacity is not None))


def _check_textures_fit(scene: Scene, device: torch.device) -> None:
    """Refuse, in one line with the figures, a scene whose textures cannot fit in ``device``'s
    memory, before any pyramid is built (shading samples them there)."""
    needed, free = pyramid_bytes(scene), free_memory(device)
    if needed > free:
        where = "memory" if device.type == "cpu" else f"{device} memory"
        raise ValueError(
            f"scene {scene.name!r}: its texture pyramids need about {needed / 2**20:.0f} MiB of {where} and "
            f"{free / 2**20:.0f} MiB are available: downscale its textures"
        )


class Surfaces:
    """The surfaces of a :class:`Scene` behind ray casters built once, and what shading reads per
    hit (texture coordinates, normals, materials), uploaded once to the casters' device.

    Args:
        scene: the scene.
        backend: the ray caster: ``"open3d"`` (Embree, CPU), ``"warp"`` (Warp's BVH on ``device``)
            or ``"auto"`` (Warp on CUDA, Open3D on the CPU).
        device: where the rays are cast and the hits shaded.
    """

    def __init__(self, scene: Scene, backend: str = "auto", device: torch.device | str = "cpu") -> None:
        self.scene = scene
        self.backend = backend
        self.caster = self.caster_of(scene.vertices, scene.faces, device)
        self.device = device = self.caster.device
        masked = np.array([m.opacity is not None for m in scene.materials], bool)[scene.material_ids]
        self._masked = masked.any()
        if self._masked:
            self._masked_face = torch.from_numpy(masked).to(device)
            self._alpha = TextureAtlas.build(
                [None if m.opacity is None else m.opacity[:, :, None] for m in scene.materials], device, mipmap=False
            )
        if self._masked and not self.caster.applies_alpha_masks:
            # A ray that met a transparent texel continues in two smaller scenes: the first hit among the
            # opaque materials' triangles, and every hit on the alpha-masked ones (a few, where listing
            # them in the whole scene would list every wall behind).
            self._opaque_faces = torch.from_numpy(np.flatnonzero(~masked)).to(device)
            self._masked_faces = torch.from_numpy(np.flatnonzero(masked)).to(device)
            self._opaque_caster = self.caster_of(scene.vertices, scene.faces[~masked], device)
            self._masked_caster = self.caster_of(scene.vertices, scene.faces[masked], device)
        _check_textures_fit(scene, device)
        self.materials = MaterialTextures(scene, device)
        self.uvs = torch.from_numpy(scene.uvs.astype(np.float64)).to(device)
        self.normals = torch.from_numpy(scene.normals.astype(np.float32)).to(device)
        self.face_normals = torch.from_numpy(scene.face_normals.astype(np.float64)).to(device)
        self.vertices = torch.from_numpy(scene.vertices.astype(np.float64)).to(device)
        self.faces = torch.from_numpy(scene.faces.astype(np.int64)).to(device)
        self.coats = torch.from_numpy(coat_table(scene)).float()[torch.from_numpy(scene.material_ids)].to(device)
        self.colors = None if scene.colors is None else torch.from_numpy(scene.colors).to(device)
        # a caster that applies the masks while it casts reads the tables see_through reads
        self._alpha_masks = self._masks_for_casting() if self._masked and self.caster.applies_alpha_masks else None

    def _masks_for_casting(self) -> AlphaMasks:
        """The alpha masks as a caster reads them while it casts: the tables :meth:`see_through`
        reads (texture coordinates, scales, the alpha atlas's full-size level), shared, not copied."""
        return AlphaMasks(
            slot=torch.where(self._masked_face, self.materials.material_ids, -1).to(torch.int32),
            corner_uvs=self.uvs.reshape(-1, 2),
            uv_scale=self.materials.uv_scale,
            texels=self._alpha.texels[:, 0].contiguous(),
            offset=self._alpha.offsets[:, 0].contiguous(),
            height=self._alpha.sizes[:, 0, 0].contiguous(),
            width=self._alpha.sizes[:, 0, 1].contiguous(),
            cutoff=_ALPHA_CUTOFF,
        )

    def caster_of(self, vertices: np.ndarray, faces: np.ndarray, device: torch.device | str | None = None) -> RayCaster:
        """A caster of triangles ``faces`` (F, 3) of ``vertices`` (V, 3) on this backend and device."""
        return make_caster(vertices, faces, self.backend, self.device if device is None else device)

    def cast(
        self,
        origins: torch.Tensor | np.ndarray,
        directions: torch.Tensor | np.ndarray,
        live: torch.Tensor | None = None,
    ) -> RayHits:
        """First opaque hits of rays (..., 3), flattened to N; alpha-masked texels let rays through.

        Rays may be tensors anywhere or host arrays; they are cast as float32 on the casters' device.
        ``live`` (N,) bool on that device: the rays to cast, the others misses (None: all).
        """
        origins, directions = _rays(self.device, origins, directions)
        if self._alpha_masks is not None:  # in the caster's traversal: one launch
            return RayHits(*self.caster.first_opaque_hits(origins, directions, live, self._alpha_masks))
        hits = first_hits(self.caster, origins, directions, live)
        if not self._masked:
            return hits
        # the few rays that met a transparent texel take their first opaque hit from one cast and one
        # list of intersections, however many leaves they pass (their number is read: one sync)
        pending = torch.nonzero(self.see_through(hits.triangle_ids, hits.barycentrics))[:, 0]
        if len(pending):
            t, ids, bary = self._first_opaque(origins.index_select(0, pending), directions.index_select(0, pending))
            hits.t[pending], hits.triangle_ids[pending], hits.barycentrics[pending] = t, ids, bary
        return hits

    def _first_opaque(self, origins: torch.Tensor, directions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """First opaque hit (t, triangle id, barycentrics) of rays (N, 3) whose first hit is a
        transparent texel: the nearer of the first hit on an opaque material's triangle and the
        first opaque texel among the hits on alpha-masked triangles."""
        t, local, bary = self._opaque_caster.first_hits(origins, directions)
        ids = torch.where(local >= 0, self._opaque_faces[local.clamp_min(0)], -1)
        ray_ids, t_masked, ids_masked, bary_masked = self._list_opaque(
            self._masked_caster, self._masked_faces, origins, directions
        )
        first = torch.ones_like(ray_ids, dtype=torch.bool)
        first[1:] = ray_ids[1:] != ray_ids[:-1]
        nearer = first & (t_masked < t[ray_ids])
        rays = ray_ids[nearer]
        t[rays], ids[rays], bary[rays] = t_masked[nearer], ids_masked[nearer], bary_masked[nearer]
        return t, ids, bary

    def intersections(
        self, origins: torch.Tensor | np.ndarray, directions: torch.Tensor | np.ndarray
    ) -> tuple[torch.Tensor, ...]:
        """Every opaque intersection of rays (N, 3), sorted by ray then distance: ray index (M,),
        parameter t (M,) float32, triangle id (M,) and barycentrics (M, 2) float32."""
        return self._list_opaque(self.caster, None, *_rays(self.device, origins, directions))

    def _list_opaque(
        self, caster: RayCaster, faces: torch.Tensor | None, origins: torch.Tensor, directions: torch.Tensor
    ) -> tuple[torch.Tensor, ...]:
        """:meth:`intersections` in ``caster``, whose triangle i is the scene's ``faces[i]`` (or i
        when ``faces`` is None)."""
        ray_ids, t, ids, bary = caster.all_hits(origins, directions)
        ids = ids if faces is None else faces[ids]
        if self._masked:
            opaque = ~self.see_through(ids, bary)
            ray_ids, t, ids, bary = ray_ids[opaque], t[opaque], ids[opaque], bary[opaque]
        # by ray, then by distance: two stable sorts
        order = torch.argsort(t, stable=True)
        order = order[torch.argsort(ray_ids[order], stable=True)]
        return ray_ids[order], t[order], ids[order], bary[order]

    def see_through(self, ids: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
        """(N,) True where hits (triangle ids (N,), barycentrics (N, 2)) fall on a transparent texel of
        an alpha mask."""
        see_through = torch.zeros_like(ids, dtype=torch.bool)
        if not self._masked:
            return see_through
        candidates = torch.nonzero((ids >= 0) & self._masked_face.index_select(0, ids.clamp_min(0)))[:, 0]
        ids, bary = ids.index_select(0, candidates), bary.index_select(0, candidates)
        material = self.materials.material_ids.index_select(0, ids)
        uv = self.interpolate(self.uvs, ids, bary) * self.materials.uv_scale.index_select(0, material)
        alpha = self._alpha.bilinear(material, torch.zeros_like(material), uv)[:, 0]
        see_through[candidates] = alpha < _ALPHA_CUTOFF
        return see_through

    def back_facing(self, hits: RayHits, directions: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(N,) True where a ray (directions (..., 3), N in all) hit the back of a triangle; False on misses."""
        (directions,) = _vectors(self.device, torch.float64, directions)
        return hits.hit & (self.facing(hits.triangle_ids.clamp_min(0), directions) > 0)

    def facing(self, triangle_ids: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        """(N,) dot products of ray directions (N, 3) with their triangles' face normals: positive
        where a ray meets the back of its triangle."""
        return dot(self.face_normals.index_select(0, triangle_ids), directions)

    @staticmethod
    def interpolate(per_corner: torch.Tensor, triangle_ids: torch.Tensor, bary: torch.Tensor) -> torch.Tensor:
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
        return coated_albedo(srgb_decode(base), self.coats.index_select(0, triangle_ids))

    def captured(self, triangle_ids: torch.Tensor, bary: torch.Tensor, footprint: torch.Tensor) -> torch.Tensor:
        """(N, 3) float32 display colour a scan shows at hits on triangles (N,) at barycentrics
        (N, 2): its vertex colours interpolated in linear light, then sRGB-encoded once; where a
        triangle has none, its material's colour or texel as stored (:meth:`albedo`)."""
        base = self.albedo(triangle_ids, bary, footprint)
        if self.colors is None:
            return base
        linear = self.interpolate(self.colors, triangle_ids, bary)
        return torch.where(torch.isnan(linear), base, srgb_encode(torch.nan_to_num(linear)))

    def albedo(self, triangle_ids: torch.Tensor, bary: torch.Tensor, footprint: torch.Tensor) -> torch.Tensor:
        """(N, 3) float32 display base colour of hits on triangles (N,) at barycentrics (N, 2),
        textures filtered to each hit's ``footprint`` (N,) metres (:meth:`MaterialTextures.albedo`)."""
        materials = self.materials
        if self.device.type != "cpu":  # a GPU computes every row sooner than it would wait for a count
            return materials.albedo(triangle_ids, self.interpolate(self.uvs, triangle_ids, bary), footprint)
        # on the CPU, texture work in proportion to the hits on textured materials (often a few)
        material = materials.material_ids.index_select(0, triangle_ids)
        colour = materials.base.index_select(0, material)
        rows = torch.nonzero(materials.textured.index_select(0, material))[:, 0]
        ids = triangle_ids.index_select(0, rows)
        uv = self.interpolate(self.uvs, ids, bary.index_select(0, rows))
        colour[rows] = materials.albedo(ids, uv, footprint.index_select(0, rows))
        return colour
