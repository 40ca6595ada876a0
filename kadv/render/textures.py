"""Texture lookups: bilinear with wrap-around, mip pyramids and trilinear filtering to a sample's
footprint, and the base colour of surface points from their materials.

Every material's pyramid lies in one flat texel buffer (:class:`TextureAtlas`) on the renderer's
device, so that hits on any number of materials are sampled by a few gathers, with no loop over
materials and nothing read back to the host. Texture coordinates are float64 (tiling can reach
hundreds of repeats); texels float32.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch.nn import functional as F

from kadv.scenes.scene import Scene

__all__ = ["MaterialTextures", "TextureAtlas", "mip_pyramid", "sample_texture", "uv_density"]


def sample_texture(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """Bilinear lookup with wrap-around (N, C) of ``texture`` (H, W, C) at ``uv`` (N, 2).

    v = 1 is the first image row (the OBJ / Mitsuba convention, which trimesh also gives glTF).
    """
    atlas = TextureAtlas.build([texture.numpy()], mipmap=False)
    first = torch.zeros(len(uv), dtype=torch.int64)
    return atlas.bilinear(first, first, uv)


def mip_pyramid(texture: np.ndarray) -> list[torch.Tensor]:
    """Box-filtered float32 levels (h, w, C) of a texture (H, W, C): level k is 2**k times coarser, down to 1 x 1."""
    current = torch.from_numpy(np.ascontiguousarray(texture, np.float32)).permute(2, 0, 1)[None]
    levels = [current[0].permute(1, 2, 0).contiguous()]
    while max(current.shape[-2:]) > 1:
        size = (max(1, current.shape[-2] // 2), max(1, current.shape[-1] // 2))
        current = F.interpolate(current, size=size, mode="area")
        levels.append(current[0].permute(1, 2, 0).contiguous())
    return levels


def uv_density(scene: Scene) -> np.ndarray:
    """(F,) texture-coordinate units per metre of each triangle (sqrt of UV area over world area)."""
    corners = scene.vertices[scene.faces]
    world = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    uv = scene.uvs.astype(np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return np.sqrt(uv_area / np.maximum(world, 1e-20))


@dataclass
class TextureAtlas:
    """Images of M slots, each with its mip levels, in one texel buffer on one device.

    Attributes:
        texels: (T, C) float32, every level of every slot, row-major.
        offsets: (M, L) int64 first texel of level l of slot m (a slot with fewer levels repeats its last).
        sizes: (M, L, 2) int64 height and width of those levels.
        top: (M,) int64 index of each slot's coarsest level.
    """

    texels: torch.Tensor
    offsets: torch.Tensor
    sizes: torch.Tensor
    top: torch.Tensor

    @classmethod
    def build(
        cls, images: list[np.ndarray | None], device: torch.device | str = "cpu", mipmap: bool = True
    ) -> TextureAtlas:
        """The atlas of ``images`` (H, W, C) (None: one texel of ones), with their mip pyramids
        (:func:`mip_pyramid`) when ``mipmap``, else level 0 alone."""
        channels = next((image.shape[2] for image in images if image is not None), 3)
        pyramids = [
            [torch.ones(1, 1, channels)]
            if image is None
            else mip_pyramid(image)
            if mipmap
            else [torch.from_numpy(np.ascontiguousarray(image, np.float32))]
            for image in images
        ]
        depth = max(len(levels) for levels in pyramids)
        offsets, sizes, start = [], [], 0
        for levels in pyramids:
            firsts = []
            for level in levels:
                firsts.append(start)
                start += level.shape[0] * level.shape[1]
            offsets.append(firsts + firsts[-1:] * (depth - len(levels)))
            shapes = [level.shape[:2] for level in levels]
            sizes.append(shapes + shapes[-1:] * (depth - len(levels)))
        texels = torch.cat([level.reshape(-1, channels) for levels in pyramids for level in levels])
        return cls(
            texels=texels.to(device),
            offsets=torch.tensor(offsets, dtype=torch.int64, device=device),
            sizes=torch.tensor(sizes, dtype=torch.int64, device=device),
            top=torch.tensor([len(levels) - 1 for levels in pyramids], dtype=torch.int64, device=device),
        )

    def bilinear(self, slot: torch.Tensor, level: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
        """(N, C) bilinear lookups with wrap-around (:func:`sample_texture`) of slots (N,) at
        levels (N,) and texture coordinates (N, 2)."""
        return self._bilinear(slot * self.offsets.shape[1] + level, *_wrapped(uv))

    def trilinear(self, slot: torch.Tensor, uv: torch.Tensor, level: torch.Tensor) -> torch.Tensor:
        """(N, C) lookups of slots (N,) at ``uv`` (N, 2), bilinear at the two mip levels around
        ``level`` (N,) (clamped to each slot's levels) and blended."""
        top = self.top.index_select(0, slot)
        level = torch.minimum(level.clamp_min(0.0), top.to(level.dtype))
        low = torch.floor(level).long()
        frac = (level - low).to(self.texels.dtype)[:, None]
        u, v = _wrapped(uv)
        first = slot * self.offsets.shape[1]
        below = self._bilinear(first + low, u, v)
        return torch.lerp(below, self._bilinear(first + torch.minimum(low + 1, top), u, v), frac)

    def _bilinear(self, entry: torch.Tensor, u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """(N, C) bilinear lookups of (slot, level) entries (N,) (flat indices into :attr:`offsets`)
        at wrapped coordinates u, v (N,) in [0, 1] (v = 0 the first row)."""
        offset = self.offsets.flatten().index_select(0, entry)
        size = self.sizes.flatten(0, 1).index_select(0, entry).to(u.dtype)
        height, width = size[:, 0], size[:, 1]
        x, y = u * width - 0.5, v * height - 0.5
        x0, y0 = torch.floor(x), torch.floor(y)
        fx, fy = (x - x0).to(self.texels.dtype)[:, None], (y - y0).to(self.texels.dtype)[:, None]
        # x0 lies in [-1, width - 1] and x0 + 1 in [0, width]: wrap-around without a division
        x1, y1 = x0 + 1.0, y0 + 1.0
        x0, y0 = torch.where(x0 < 0, x0 + width, x0), torch.where(y0 < 0, y0 + height, y0)
        x1, y1 = torch.where(x1 >= width, x1 - width, x1), torch.where(y1 >= height, y1 - height, y1)
        top, bottom = (y0 * width).long() + offset, (y1 * width).long() + offset
        x0, x1 = x0.long(), x1.long()

        def tap(row: torch.Tensor, column: torch.Tensor) -> torch.Tensor:
            # one gather per corner: contiguous (N, C) rows, which the blends read faster than (N, 4, C)
            return self.texels.index_select(0, row + column)

        upper = torch.lerp(tap(top, x0), tap(top, x1), fx)
        return torch.lerp(upper, torch.lerp(tap(bottom, x0), tap(bottom, x1), fx), fy)


def _wrapped(uv: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Texture coordinates (N, 2) wrapped into the unit square, v flipped (v = 1 is the first row)."""
    return torch.remainder(uv[:, 0], 1.0), torch.remainder(1.0 - uv[:, 1], 1.0)


class MaterialTextures:
    """A scene's materials as shading reads them, on one device: base colours, texture-coordinate
    scales and textures (:class:`TextureAtlas`, untextured materials a texel of ones), which
    materials have a texture, and each triangle's material and texel density (:func:`uv_density`).

    Args:
        scene: the scene.
        device: where the tables live and the lookups run.
    """

    def __init__(self, scene: Scene, device: torch.device | str = "cpu") -> None:
        materials = scene.materials
        self.atlas = TextureAtlas.build([m.texture for m in materials], device)
        self.base = torch.tensor(np.array([m.base_color for m in materials], np.float32).reshape(-1, 3), device=device)
        self.uv_scale = torch.tensor(
            np.array([m.uv_scale for m in materials], np.float64).reshape(-1, 2), device=device
        )
        # texels per texture-coordinate unit along an axis, for the mip level
        per_unit = [
            np.sqrt(m.texture.shape[0] * m.texture.shape[1]) * float(np.sqrt(np.prod(m.uv_scale)))
            if m.texture is not None
            else 1.0
            for m in materials
        ]
        self.texels_per_unit = torch.tensor(per_unit, dtype=torch.float32, device=device)
        self.material_ids = torch.from_numpy(scene.material_ids.astype(np.int64)).to(device)
        self.textured = torch.tensor([m.texture is not None for m in materials], dtype=torch.bool).to(device)
        self.density = torch.from_numpy(uv_density(scene).astype(np.float32)).to(device)

    def albedo(self, triangle_ids: torch.Tensor, uv: torch.Tensor, footprint: torch.Tensor) -> torch.Tensor:
        """Base colour (N, 3) float32 of surface points on triangles (N,) at texture coordinates (N, 2).

        Textures are prefiltered (mip-mapped) to each sample's ``footprint`` (N,) (metres of surface
        one sample covers) through the triangle's texel density, so renders are band-limited and
        smooth in the camera pose.
        """
        material = self.material_ids.index_select(0, triangle_ids)
        texel_footprint = footprint * self.density.index_select(0, triangle_ids)
        texel_footprint = texel_footprint * self.texels_per_unit.index_select(0, material)
        level = torch.log2(texel_footprint.clamp_min(1.0))
        filtered = self.atlas.trilinear(material, uv * self.uv_scale.index_select(0, material), level)
        return self.base.index_select(0, material) * filtered
