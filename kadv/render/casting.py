"""Ray casting behind one small interface, so the renderer, the layers, the silhouette term, the
validity checks, the bake and the penalty are written once for every backend.

Two backends implement :class:`RayCaster`: Open3D's Embree ``RaycastingScene`` (here, the CPU
default) and NVIDIA Warp's BVH (:mod:`kadv.render.warp_caster`, on CUDA or Warp's CPU device).
:func:`kadv.render.backends.make_caster` picks one. Rays and results are torch tensors on the
caster's device.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import open3d as o3d
import torch

__all__ = ["AlphaMasks", "Open3DCaster", "RayCaster"]


@dataclass(frozen=True)
class AlphaMasks:
    """Alpha-masked materials as a caster's traversal reads them, on its device.

    A hit on triangle f with ``slot[f]`` >= 0 is looked up in that slot's mask at the texture
    coordinates ``uv_scale[slot]`` x (the corners' ``corner_uvs`` interpolated at the hit), bilinearly
    with wrap-around, v = 1 the first row (as :class:`~kadv.render.textures.TextureAtlas` samples);
    a ray passes through where the mask is below ``cutoff``.

    Attributes:
        slot: (F,) int32 each triangle's mask (its material), -1 for an opaque material.
        corner_uvs: (F * 3, 2) float64 texture coordinates of the triangles' corners.
        uv_scale: (M, 2) float64 per mask.
        texels: (T,) float32 every mask's texels, row-major.
        offset: (M,) int64 each mask's first texel.
        height: (M,) int64 and width: (M,) int64 each mask's size.
        cutoff: opacity below which a texel lets rays through.
    """

    slot: torch.Tensor
    corner_uvs: torch.Tensor
    uv_scale: torch.Tensor
    texels: torch.Tensor
    offset: torch.Tensor
    height: torch.Tensor
    width: torch.Tensor
    cutoff: float


class RayCaster(ABC):
    """Ray queries against one triangle mesh; triangle ids are the rows of its ``faces``.

    Barycentrics follow Open3D: a hit (u, v) on triangle (a, b, c) lies at (1 - u - v) a + u b + v c.
    Rays are (N, 3) float32 origins and directions on :attr:`device`; t is the ray parameter
    (z-depth for directions with z = 1).
    """

    device: torch.device

    @abstractmethod
    def first_hits(
        self, origins: torch.Tensor, directions: torch.Tensor, live: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, ...]:
        """First hit of each ray: t (N,) float32 (inf on a miss), triangle id (N,) int64 (-1 on a miss)
        and barycentrics (N, 2) float32. ``live`` (N,) bool: the rays to cast; the others come back
        as misses (None: all)."""

    #: whether :meth:`first_opaque_hits` applies alpha masks within the traversal
    applies_alpha_masks: bool = False

    def first_opaque_hits(
        self, origins: torch.Tensor, directions: torch.Tensor, live: torch.Tensor | None, masks: AlphaMasks
    ) -> tuple[torch.Tensor, ...]:
        """:meth:`first_hits` that passes through transparent texels of ``masks``, for casters whose
        :attr:`applies_alpha_masks`; the others leave masks to :class:`~kadv.render.surface.Surfaces`."""
        raise NotImplementedError(f"{type(self).__name__} does not apply alpha masks while it casts")

    @abstractmethod
    def all_hits(self, origins: torch.Tensor, directions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Every hit of the rays, in no order: ray index (M,) int64, t (M,) float32, triangle id (M,)
        int64 and barycentrics (M, 2) float32."""

    @abstractmethod
    def closest_points(self, points: torch.Tensor) -> torch.Tensor:
        """(N, 3) float32 closest surface point to each of ``points`` (N, 3) float32."""


class Open3DCaster(RayCaster):
    """Open3D's Embree ``RaycastingScene`` on the CPU."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        self.device = torch.device("cpu")
        self.scene = o3d.t.geometry.RaycastingScene()
        if len(faces):
            self.scene.add_triangles(
                o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32))
            )

    @staticmethod
    def _rays(origins: torch.Tensor, directions: torch.Tensor) -> o3d.core.Tensor:
        # one copy into Open3D's (N, 6) layout, whose memory Open3D then shares
        return o3d.core.Tensor.from_numpy(torch.cat([origins, directions], dim=1).numpy())

    def first_hits(
        self, origins: torch.Tensor, directions: torch.Tensor, live: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, ...]:
        if live is None:
            return self._first_hits(origins, directions)
        # Embree casts every ray of a call: the live ones alone are cast (a depth peel's later casts
        # have a few per cent of them), the others reported as misses
        rows = torch.nonzero(live)[:, 0]
        t = torch.full((len(live),), torch.inf, dtype=torch.float32)
        ids = torch.full((len(live),), -1, dtype=torch.int64)
        bary = torch.zeros(len(live), 2, dtype=torch.float32)
        if len(rows):
            found = self._first_hits(origins.index_select(0, rows), directions.index_select(0, rows))
            for into, values in zip((t, ids, bary), found):
                into.index_copy_(0, rows, values)
        return t, ids, bary

    def _first_hits(self, origins: torch.Tensor, directions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        result = self.scene.cast_rays(self._rays(origins, directions))
        # Open3D's ids are uint32, 2**32 - 1 on a miss: read as int32, that is -1 (and scenes have far
        # fewer than 2**31 triangles); one conversion instead of a comparison and a select
        ids = torch.from_numpy(result["primitive_ids"].numpy().view(np.int32)).long()
        return torch.from_numpy(result["t_hit"].numpy()), ids, torch.from_numpy(result["primitive_uvs"].numpy())

    def all_hits(self, origins: torch.Tensor, directions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        if len(origins) == 0:  # Open3D's list_intersections crashes the process on no rays
            return torch.zeros(0, dtype=torch.long), torch.zeros(0), torch.zeros(0, dtype=torch.long), torch.zeros(0, 2)
        result = self.scene.list_intersections(self._rays(origins, directions))
        return (
            torch.from_numpy(result["ray_ids"].numpy()).long(),
            torch.from_numpy(result["t_hit"].numpy()),
            torch.from_numpy(result["primitive_ids"].numpy()).long(),
            torch.from_numpy(result["primitive_uvs"].numpy()),
        )

    def closest_points(self, points: torch.Tensor) -> torch.Tensor:
        query = o3d.core.Tensor.from_numpy(np.ascontiguousarray(points.numpy()))
        return torch.from_numpy(self.scene.compute_closest_points(query)["points"].numpy())
