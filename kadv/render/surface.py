"""What a ray hit: the scene's triangles behind ray casters of one backend, alpha-masked texels
that let rays through, and per hit its texture coordinates, shading normal, side and albedo.

The renderer (:mod:`kadv.render.raycast`), the bake, the layers, the silhouette term and the
validity checks all cast through one :class:`Surfaces`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from kadv.device import free_memory
from kadv.geometry.vector import dot
from kadv.render.backends import make_caster
from kadv.render.casting import RayCaster
from kadv.render.colour import coat_table, coated_albedo, srgb_decode
from kadv.render.textures import albedo, mip_pyramid, sample_texture, uv_density
from kadv.scenes.scene import Scene

__all__ = ["RayHits", "Surfaces", "first_hits", "pyramid_bytes"]

_ALPHA_CUTOFF = 0.5


@dataclass
class RayHits:
    """Hits of N rays: parameter t (z-depth for z=1 directions), triangle id (-1 = miss), barycentrics."""

    t: np.ndarray
    triangle_ids: np.ndarray
    barycentrics: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.triangle_ids >= 0


def first_hits(
    caster: RayCaster, origins: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First hits of rays (N, 3): t (inf on a miss), triangle id (-1 on a miss) and barycentrics."""
    t, ids, bary = caster.first_hits(*_rays(caster, origins, directions))
    return t.cpu().numpy().astype(np.float64), ids.cpu().numpy(), bary.cpu().numpy().astype(np.float64)


def _rays(caster: RayCaster, *arrays: np.ndarray) -> list[torch.Tensor]:
    """float32 tensors on the caster's device of arrays (N, 3)."""
    return [torch.from_numpy(np.asarray(a, np.float32).reshape(-1, 3)).to(caster.device) for a in arrays]


def pyramid_bytes(scene: Scene) -> int:
    """Bytes of the scene's texture pyramids (float32 levels, each a quarter of the one before:
    4/3 of the full-size level) and alpha masks."""
    texels = sum(m.texture.size * 4 // 3 for m in scene.materials if m.texture is not None)
    return 4 * (texels + sum(m.opacity.size for m in scene.materials if m.opacity is not None))


def _check_textures_fit(scene: Scene) -> None:
    """Refuse, in one line with the figures, a scene whose textures cannot fit in memory, before any
    pyramid is built (shading samples them on the host)."""
    needed, free = pyramid_bytes(scene), free_memory("cpu")
    if needed > free:
        raise ValueError(
            f"scene {scene.name!r}: its texture pyramids need about {needed / 2**20:.0f} MiB of memory and "
            f"{free / 2**20:.0f} MiB are available: downscale its textures"
        )


class Surfaces:
    """The surfaces of a :class:`Scene` behind ray casters built once.

    Args:
        scene: the scene.
        backend: the ray caster: ``"open3d"`` (Embree, CPU), ``"warp"`` (Warp's BVH on ``device``)
            or ``"auto"`` (Warp on CUDA, Open3D on the CPU).
        device: where the rays are cast.
    """

    def __init__(self, scene: Scene, backend: str = "auto", device: torch.device | str = "cpu") -> None:
        self.scene = scene
        self.backend, self.device = backend, device
        self.caster = self.caster_of(scene.vertices, scene.faces)
        # A ray that met a transparent texel continues in two smaller scenes: the first hit among the
        # opaque materials' triangles, and every hit on the alpha-masked ones (a few, where listing
        # them in the whole scene would list every wall behind).
        masked_faces = np.array([m.opacity is not None for m in scene.materials], bool)[scene.material_ids]
        self._masked_face = np.r_[masked_faces, False]  # per triangle, and a False that a miss (id -1) reads
        self._opaque_faces, self._masked_faces = np.flatnonzero(~masked_faces), np.flatnonzero(masked_faces)
        if len(self._masked_faces):
            self._opaque_caster = self.caster_of(scene.vertices, scene.faces[self._opaque_faces])
            self._masked_caster = self.caster_of(scene.vertices, scene.faces[self._masked_faces])
        # shading reads these per hit: torch copies made once
        _check_textures_fit(scene)
        self.pyramids = {i: mip_pyramid(m.texture) for i, m in enumerate(scene.materials) if m.texture is not None}
        self.opacity = {
            i: torch.from_numpy(np.ascontiguousarray(m.opacity[:, :, None], np.float32))
            for i, m in enumerate(scene.materials)
            if m.opacity is not None
        }
        self.texel_density = torch.from_numpy(uv_density(scene).astype(np.float32))
        self.uvs = torch.from_numpy(scene.uvs.astype(np.float64))
        self.normals = torch.from_numpy(scene.normals.astype(np.float32))
        self.face_normals = torch.from_numpy(scene.face_normals.astype(np.float64))
        self.coats = torch.from_numpy(coat_table(scene)).float()[torch.from_numpy(scene.material_ids)]

    def caster_of(self, vertices: np.ndarray, faces: np.ndarray) -> RayCaster:
        """A caster of triangles ``faces`` (F, 3) of ``vertices`` (V, 3) on this backend and device."""
        return make_caster(vertices, faces, self.backend, self.device)

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """Cast rays (..., 3) each; alpha-masked texels let rays through.

        Returns:
            Hits flattened to N = prod(...) rays.
        """
        origins = origins.reshape(-1, 3)
        directions = directions.reshape(-1, 3)
        t, ids, bary = first_hits(self.caster, origins, directions)
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
        t, local, bary = first_hits(self._opaque_caster, origins, directions)
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
            uv = self.interpolate(self.uvs, torch.from_numpy(ids[selected]), torch.from_numpy(bary[selected]))
            uv_scale = torch.as_tensor(self.scene.materials[index].uv_scale, dtype=uv.dtype)
            alpha = sample_texture(self.opacity[index], uv * uv_scale)[:, 0]
            see_through[selected[(alpha < _ALPHA_CUTOFF).numpy()]] = True
        return see_through

    def back_facing(self, hits: RayHits, directions: np.ndarray) -> np.ndarray:
        """(N,) True where a ray (directions (..., 3), N in all) hit the back of a triangle; False on misses."""
        # a copy: the directions may be a read-only broadcast view
        facing = self.facing(
            torch.from_numpy(np.maximum(hits.triangle_ids, 0)),
            torch.tensor(directions.reshape(-1, 3), dtype=torch.float64),
        )
        return hits.hit & (facing > 0).numpy()

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

    def albedo(self, triangle_ids: torch.Tensor, uv: torch.Tensor, footprint: torch.Tensor) -> torch.Tensor:
        """(N, 3) float32 display base colour of hits on triangles (N,) at texture coordinates (N, 2),
        textures filtered to each hit's ``footprint`` (N,) metres (:func:`kadv.render.textures.albedo`)."""
        return albedo(self.scene, triangle_ids, uv, footprint, self.pyramids, self.texel_density)
