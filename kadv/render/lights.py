"""Light that reaches surface points straight from the scene's emitters, with shadow rays (area
emitters sampled by area and power; point and spot lights and suns, exactly), the sky seen along a
direction, and where the direct shading's lights stand."""

from __future__ import annotations

import numpy as np

from kadv.render.colour import LUMINANCE
from kadv.render.surface import Surfaces
from kadv.scenes.emitters import MISSING_ENVMAP_RADIANCE, Emitters
from kadv.scenes.scene import Scene

__all__ = ["SURFACE_OFFSET", "area_irradiance", "delta_irradiance", "scene_lights", "sky_emitters", "sky_radiance"]

SURFACE_OFFSET = 1e-3  # metres: ray origins leave the surface by this much, and keep as far from its edges


def scene_lights(scene: Scene, lights: tuple[tuple[float, float, float], ...] | None = None) -> np.ndarray:
    """The direct shading's light positions (L, 3): ``lights`` (configured), else the file's
    emitters, else above the bounds centre."""
    if lights is not None:
        return np.asarray(lights, np.float64).reshape(-1, 3)
    if len(scene.lights):
        return scene.lights
    lo, hi = scene.bounds
    return np.array([[(lo[0] + hi[0]) / 2, lo[1] + 0.9 * (hi[1] - lo[1]), (lo[2] + hi[2]) / 2]])


def sky_emitters(scene: Scene) -> Emitters:
    """The emitters whose sky the bake saw: the scene's, or the default uniform sky."""
    return scene.emitters if not scene.emitters.empty else Emitters(sky_radiance=np.full(3, MISSING_ENVMAP_RADIANCE))


def sky_radiance(emitters: Emitters, directions: np.ndarray) -> np.ndarray:
    """(N, 3) radiance of the sky seen along unit ``directions`` (N, 3)."""
    if emitters.envmap is None:
        return np.broadcast_to(emitters.sky_radiance, directions.shape)
    local = directions @ emitters.envmap_world_T_map  # the map's frame: the rotation's inverse
    # Mitsuba's latitude-longitude layout: u from the azimuth about +y, v = 0 at +y
    u = (np.arctan2(local[:, 0], -local[:, 2]) / (2.0 * np.pi)) % 1.0
    v = np.arccos(np.clip(local[:, 1], -1.0, 1.0)) / np.pi
    height, width = emitters.envmap.shape[:2]
    rows = np.minimum((v * height).astype(np.int64), height - 1)
    columns = np.minimum((u * width).astype(np.int64), width - 1)
    return emitters.envmap[rows, columns].astype(np.float64)


def _visible(surfaces: Surfaces, origins: np.ndarray, directions: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """(N,) True where nothing lies between ``origins`` and ``distance`` along unit ``directions``."""
    hits = surfaces.cast(origins, directions)
    return hits.t >= distance * (1.0 - 1e-6) - SURFACE_OFFSET


def area_irradiance(
    surfaces: Surfaces, emitters: Emitters, points: np.ndarray, normals: np.ndarray, rng: np.random.Generator,
    light_samples: int,
) -> np.ndarray:  # fmt: skip
    """(N, 3) irradiance from the area emitters, with shadows (``light_samples`` shadow rays each)."""
    irradiance = np.zeros((len(points), 3))
    origins = points + SURFACE_OFFSET * normals
    triangles = emitters.area_triangles
    if not len(triangles):
        return irradiance
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    light_normals = cross / np.maximum(2.0 * area, 1e-30)[:, None]
    power = area * (emitters.area_radiance @ LUMINANCE)
    if power.sum() <= 0:
        return irradiance
    probability = power / power.sum()
    for _ in range(light_samples):
        chosen = rng.choice(len(triangles), size=len(points), p=probability)
        s, t = rng.random((2, len(points)))
        root = np.sqrt(s)
        tri = triangles[chosen]
        target = (1 - root)[:, None] * tri[:, 0] + (root * (1 - t))[:, None] * tri[:, 1]
        target = target + (root * t)[:, None] * tri[:, 2]
        offset = target - origins
        distance = np.linalg.norm(offset, axis=1)
        direction = offset / np.maximum(distance, 1e-12)[:, None]
        cos_receiver = np.einsum("nd,nd->n", direction, normals).clip(0.0)
        cos_light = -np.einsum("nd,nd->n", direction, light_normals[chosen]).clip(max=0.0)
        geometry = cos_receiver * cos_light / np.maximum(distance, 1e-3) ** 2 * area[chosen] / probability[chosen]
        lit = (geometry > 0) & _visible(surfaces, origins, direction, distance)
        irradiance += (emitters.area_radiance[chosen] * (geometry * lit)[:, None]) / light_samples
    return irradiance


def delta_irradiance(surfaces: Surfaces, emitters: Emitters, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) irradiance at surface points (N, 3) with unit normals (N, 3) from the lights of no
    extent (point and spot lights, directional suns), one shadow ray each: exact, so the renderer
    shades it per hit and the bake carries only its bounces."""
    irradiance = np.zeros((len(points), 3))
    origins = points + SURFACE_OFFSET * normals
    for index, position in enumerate(emitters.point_positions):
        offset = position - origins
        distance = np.linalg.norm(offset, axis=1)
        direction = offset / np.maximum(distance, 1e-12)[:, None]
        falloff = np.ones(len(points))
        if emitters.spot_cos_cutoff[index] > -1.0:
            cos_axis = -direction @ emitters.spot_directions[index]
            angle, beam = np.arccos(np.clip(cos_axis, -1, 1)), np.arccos(emitters.spot_cos_beam[index])
            cutoff = np.arccos(emitters.spot_cos_cutoff[index])
            falloff = np.clip((cutoff - angle) / max(cutoff - beam, 1e-9), 0.0, 1.0)
        cosine = np.einsum("nd,nd->n", direction, normals).clip(0.0) * falloff
        lit = (cosine > 0) & _visible(surfaces, origins, direction, distance)
        irradiance += emitters.point_intensity[index] * (cosine * lit / np.maximum(distance, 1e-3) ** 2)[:, None]
    for direction, sun in zip(emitters.sun_directions, emitters.sun_irradiance):
        directions = np.broadcast_to(direction, origins.shape)
        cosine = normals @ direction
        lit = (cosine > 0) & ~surfaces.cast(origins, directions).hit
        irradiance += sun * (cosine.clip(0.0) * lit)[:, None]
    return irradiance
