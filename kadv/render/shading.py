"""View-independent shading: base colour (texture or constant) x (ambient + Lambertian world lights).

A surface point keeps its colour when the camera moves (no head-light, no specular term): the
differentiable reprojection relies on it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kadv.scenes.scene import Scene

__all__ = ["Shading", "sample_texture", "scene_lights", "shade"]


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


def albedo(scene: Scene, triangle_ids: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Base colour (N, 3) of surface points given their triangles (N,) and texture coordinates (N, 2)."""
    material_ids = scene.material_ids[triangle_ids]
    colour = np.empty((len(triangle_ids), 3), np.float32)
    for index in np.unique(material_ids):
        material = scene.materials[index]
        selected = material_ids == index
        colour[selected] = material.base_color
        if material.texture is not None:
            colour[selected] *= sample_texture(material.texture, uv[selected] * material.uv_scale)
    return colour


def shade(scene: Scene, shading: Shading, lights: np.ndarray, triangle_ids: np.ndarray, uv: np.ndarray,
          points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Shaded RGB (N, 3) in [0, 1] of surface points with unit normals facing the viewer side."""
    to_lights = lights[None, :, :] - points[:, None, :]
    to_lights /= np.maximum(np.linalg.norm(to_lights, axis=-1, keepdims=True), 1e-9)
    lambert = np.clip(np.einsum("nlc,nc->nl", to_lights, normals), 0.0, None).mean(axis=1)
    light = shading.ambient + shading.diffuse * lambert
    return np.clip(albedo(scene, triangle_ids, uv) * light[:, None], 0.0, 1.0)
