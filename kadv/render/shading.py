"""View-independent shading: base colour (texture or constant) x (ambient + Lambertian world lights).

A surface point keeps its colour when the camera moves (no head-light, no specular term): the
differentiable reprojection relies on it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch.nn import functional as F

from kadv.scenes.scene import Scene

__all__ = ["Shading", "mip_pyramid", "sample_texture", "sample_texture_filtered", "scene_lights", "shade", "uv_density"]


@dataclass(frozen=True)
class Shading:
    """Shading parameters.

    Attributes:
        ambient: constant term in [0, 1].
        diffuse: weight of the Lambertian term, split evenly over the lights.
        lights: (L, 3) world positions; None uses the scene's emitters, else a light placed from
            the scene bounds.
        background: RGB of rays that hit nothing.
    """

    ambient: float = 0.45
    diffuse: float = 0.55
    lights: tuple[tuple[float, float, float], ...] | None = None
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)


def scene_lights(scene: Scene, shading: Shading) -> np.ndarray:
    """Light positions (L, 3): configured, else the file's emitters, else above the bounds centre."""
    if shading.lights is not None:
        return np.asarray(shading.lights, np.float64).reshape(-1, 3)
    if len(scene.lights):
        return scene.lights
    lo, hi = scene.bounds
    return np.array([[(lo[0] + hi[0]) / 2, lo[1] + 0.9 * (hi[1] - lo[1]), (lo[2] + hi[2]) / 2]])


def sample_texture(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup with wrap-around (N, C) of ``texture`` (H, W, C) at ``uv`` (N, 2).

    v = 1 is the first image row (the OBJ / Mitsuba convention, which trimesh also gives glTF).
    """
    height, width = texture.shape[:2]
    x = np.mod(uv[:, 0], 1.0) * width - 0.5
    y = np.mod(1.0 - uv[:, 1], 1.0) * height - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64) % width, y0.astype(np.int64) % height
    x1, y1 = (x0 + 1) % width, (y0 + 1) % height
    top = texture[y0, x0] * (1 - fx) + texture[y0, x1] * fx
    bottom = texture[y1, x0] * (1 - fx) + texture[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def mip_pyramid(texture: np.ndarray) -> list[np.ndarray]:
    """Box-filtered levels of a texture (H, W, C): level k is 2**k times coarser, down to 1 x 1."""
    levels = [texture.astype(np.float32)]
    current = torch.from_numpy(levels[0]).permute(2, 0, 1)[None]
    while max(current.shape[-2:]) > 1:
        size = (max(1, current.shape[-2] // 2), max(1, current.shape[-1] // 2))
        current = F.interpolate(current, size=size, mode="area")
        levels.append(current[0].permute(1, 2, 0).numpy())
    return levels


def sample_texture_filtered(levels: list[np.ndarray], uv: np.ndarray, level: np.ndarray) -> np.ndarray:
    """Trilinear lookup (N, C): bilinear at the two mip levels around ``level`` (N,), blended."""
    level = np.clip(level, 0.0, len(levels) - 1)
    low = np.floor(level).astype(np.int64)
    frac = (level - low)[:, None]
    out = np.zeros((len(uv), levels[0].shape[2]), np.float64)
    for index in np.unique(low):
        selected = low == index
        below = sample_texture(levels[index], uv[selected])
        above = sample_texture(levels[min(index + 1, len(levels) - 1)], uv[selected])
        out[selected] = below * (1 - frac[selected]) + above * frac[selected]
    return out


def uv_density(scene: Scene) -> np.ndarray:
    """(F,) texture-coordinate units per metre of each triangle (sqrt of UV area over world area)."""
    corners = scene.vertices[scene.faces]
    world = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    uv = scene.uvs.astype(np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return np.sqrt(uv_area / np.maximum(world, 1e-20))


def albedo(scene: Scene, triangle_ids: np.ndarray, uv: np.ndarray, footprint: np.ndarray,
           pyramids: dict[int, list[np.ndarray]], density: np.ndarray) -> np.ndarray:
    """Base colour (N, 3) of surface points given their triangles (N,) and texture coordinates (N, 2).

    Textures are prefiltered (mip-mapped, from ``pyramids`` per material index) to each sample's
    ``footprint`` (N,) (metres of surface one sample covers) using the per-triangle UV ``density``,
    so renders are band-limited and smooth in the camera pose.
    """
    material_ids = scene.material_ids[triangle_ids]
    colour = np.empty((len(triangle_ids), 3), np.float32)
    for index in np.unique(material_ids):
        material = scene.materials[index]
        selected = material_ids == index
        colour[selected] = material.base_color
        if material.texture is not None:
            texels = np.sqrt(material.texture.shape[0] * material.texture.shape[1])
            scale = float(np.sqrt(np.prod(material.uv_scale)))
            texel_footprint = footprint[selected] * density[triangle_ids[selected]] * scale * texels
            level = np.log2(np.maximum(texel_footprint, 1.0))
            colour[selected] *= sample_texture_filtered(pyramids[index], uv[selected] * material.uv_scale, level)
    return colour


def shade(shading: Shading, lights: np.ndarray, points: np.ndarray, normals: np.ndarray,
          base_colour: np.ndarray) -> np.ndarray:
    """Shaded RGB (N, 3) in [0, 1] of surface points with unit normals facing the viewer side."""
    to_lights = lights[None, :, :] - points[:, None, :]
    to_lights /= np.maximum(np.linalg.norm(to_lights, axis=-1, keepdims=True), 1e-9)
    lambert = np.clip(np.einsum("nlc,nc->nl", to_lights, normals), 0.0, None).mean(axis=1)
    light = shading.ambient + shading.diffuse * lambert
    return np.clip(base_colour * light[:, None], 0.0, 1.0)
