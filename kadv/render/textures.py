"""Texture lookups: bilinear with wrap-around, mip pyramids and trilinear filtering to a sample's
footprint, and the base colour of surface points from their materials.

Texture coordinates are float64 (tiling can reach hundreds of repeats); texels float32.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional as F

from kadv.scenes.scene import Scene

__all__ = ["albedo", "mip_pyramid", "sample_texture", "sample_texture_filtered", "uv_density"]


def sample_texture(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """Bilinear lookup with wrap-around (N, C) of ``texture`` (H, W, C) at ``uv`` (N, 2).

    v = 1 is the first image row (the OBJ / Mitsuba convention, which trimesh also gives glTF).
    """
    height, width, channels = texture.shape
    x = torch.remainder(uv[:, 0], 1.0) * width - 0.5
    y = torch.remainder(1.0 - uv[:, 1], 1.0) * height - 0.5
    x0, y0 = torch.floor(x), torch.floor(y)
    fx, fy = (x - x0).to(texture.dtype)[:, None], (y - y0).to(texture.dtype)[:, None]
    x0, y0 = x0.long() % width, y0.long() % height
    x1, y1 = (x0 + 1) % width, (y0 + 1) % height
    # the four taps in one index_select (several times faster than indexing with [ ] on the CPU)
    rows, columns = torch.cat([y0, y0, y1, y1]) * width, torch.cat([x0, x1, x0, x1])
    taps = texture.reshape(-1, channels).index_select(0, rows + columns)
    top_left, top_right, bottom_left, bottom_right = taps.split(len(uv))
    top = torch.lerp(top_left, top_right, fx)
    bottom = torch.lerp(bottom_left, bottom_right, fx)
    return torch.lerp(top, bottom, fy)


def mip_pyramid(texture: np.ndarray) -> list[torch.Tensor]:
    """Box-filtered float32 levels (h, w, C) of a texture (H, W, C): level k is 2**k times coarser, down to 1 x 1."""
    current = torch.from_numpy(np.ascontiguousarray(texture, np.float32)).permute(2, 0, 1)[None]
    levels = [current[0].permute(1, 2, 0).contiguous()]
    while max(current.shape[-2:]) > 1:
        size = (max(1, current.shape[-2] // 2), max(1, current.shape[-1] // 2))
        current = F.interpolate(current, size=size, mode="area")
        levels.append(current[0].permute(1, 2, 0).contiguous())
    return levels


def sample_texture_filtered(levels: list[torch.Tensor], uv: torch.Tensor, level: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup (N, C): bilinear at the two mip levels around ``level`` (N,), blended."""
    level = level.clamp(0.0, len(levels) - 1)
    low = torch.floor(level).long()
    frac = (level - low).to(levels[0].dtype)[:, None]
    out = torch.empty(len(uv), levels[0].shape[2], dtype=levels[0].dtype)
    for index in torch.unique(low).tolist():
        selected = torch.nonzero(low == index)[:, 0]
        uv_selected = uv.index_select(0, selected)
        below = sample_texture(levels[index], uv_selected)
        above = sample_texture(levels[min(index + 1, len(levels) - 1)], uv_selected)
        out.index_copy_(0, selected, torch.lerp(below, above, frac.index_select(0, selected)))
    return out


def uv_density(scene: Scene) -> np.ndarray:
    """(F,) texture-coordinate units per metre of each triangle (sqrt of UV area over world area)."""
    corners = scene.vertices[scene.faces]
    world = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    uv = scene.uvs.astype(np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return np.sqrt(uv_area / np.maximum(world, 1e-20))


def albedo(
    scene: Scene,
    triangle_ids: torch.Tensor,
    uv: torch.Tensor,
    footprint: torch.Tensor,
    pyramids: dict[int, list[torch.Tensor]],
    density: torch.Tensor,
) -> torch.Tensor:
    """Base colour (N, 3) float32 of surface points given their triangles (N,) and texture coordinates (N, 2).

    Textures are prefiltered (mip-mapped, from ``pyramids`` per material index) to each sample's
    ``footprint`` (N,) (metres of surface one sample covers) using the per-triangle UV ``density``
    (F,), so renders are band-limited and smooth in the camera pose.
    """
    material_ids = scene.material_ids[triangle_ids.numpy()]
    # samples grouped by material: one sort instead of a full-length mask per material (numpy's
    # stable sort is several times faster than torch's on the CPU here, and a radix sort on ids
    # of 16 bits or fewer)
    narrow = material_ids.astype(np.min_scalar_type(max(len(scene.materials) - 1, 0)))
    order = torch.from_numpy(np.argsort(narrow, kind="stable"))
    counts = np.bincount(material_ids, minlength=len(scene.materials)).tolist()
    colour = torch.empty(len(triangle_ids), 3, dtype=torch.float32)
    start = 0
    for index, count in enumerate(counts):
        if not count:
            continue
        selected = order[start : start + count]
        start += count
        material = scene.materials[index]
        base = torch.as_tensor(material.base_color, dtype=torch.float32).expand(count, 3)
        if material.texture is None:
            colour.index_copy_(0, selected, base)
            continue
        texels = np.sqrt(material.texture.shape[0] * material.texture.shape[1])
        scale = float(np.sqrt(np.prod(material.uv_scale)))
        density_selected = density.index_select(0, triangle_ids.index_select(0, selected))
        texel_footprint = footprint.index_select(0, selected) * density_selected * (scale * texels)
        level = torch.log2(texel_footprint.clamp_min(1.0))
        uv_scale = torch.as_tensor(material.uv_scale, dtype=uv.dtype)
        filtered = sample_texture_filtered(pyramids[index], uv.index_select(0, selected) * uv_scale, level)
        colour.index_copy_(0, selected, base * filtered)
    return colour
