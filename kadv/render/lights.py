"""Light that reaches surface points straight from the scene's emitters, with shadow rays (area
emitters sampled by area and power; point and spot lights and suns, exactly), the sky seen along a
direction, and where the direct shading's lights stand."""

from __future__ import annotations

import math

import numpy as np
import torch

from kadv.geometry.vector import dot
from kadv.render.colour import LUMINANCE
from kadv.render.surface import Surfaces
from kadv.scenes.emitters import MISSING_ENVMAP_RADIANCE, Emitters
from kadv.scenes.scene import Scene

__all__ = ["SURFACE_OFFSET", "DeltaLights", "Sky", "area_irradiance", "scene_lights", "sky_emitters"]

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


class Sky:
    """The radiance of the sky the bake was lit by (:func:`sky_emitters`), as seen along a
    direction, with its tables on one device.

    Args:
        emitters: the emitters whose uniform sky or environment map this is.
        device: where the lookups run.
    """

    def __init__(self, emitters: Emitters, device: torch.device | str = "cpu") -> None:
        self.radiance = torch.from_numpy(np.asarray(emitters.sky_radiance, np.float64)).to(device)
        self.envmap = (
            None if emitters.envmap is None else torch.from_numpy(emitters.envmap.astype(np.float64)).to(device)
        )
        self.world_T_map = torch.from_numpy(np.asarray(emitters.envmap_world_T_map, np.float64)).to(device)

    def __call__(self, directions: torch.Tensor) -> torch.Tensor:
        """(N, 3) float64 radiance seen along unit ``directions`` (N, 3) float64."""
        if self.envmap is None:
            return self.radiance.expand(len(directions), 3)
        local = directions @ self.world_T_map  # the map's frame: the rotation's inverse
        # Mitsuba's latitude-longitude layout: u from the azimuth about +y, v = 0 at +y
        u = torch.remainder(torch.atan2(local[:, 0], -local[:, 2]) / (2.0 * math.pi), 1.0)
        v = torch.arccos(local[:, 1].clamp(-1.0, 1.0)) / math.pi
        height, width = self.envmap.shape[:2]
        rows = (v * height).long().clamp_max(height - 1)
        columns = (u * width).long().clamp_max(width - 1)
        return self.envmap.flatten(0, 1).index_select(0, rows * width + columns)


def _visible(
    surfaces: Surfaces, origins: torch.Tensor, directions: torch.Tensor, distance: torch.Tensor
) -> torch.Tensor:
    """(N,) True where nothing lies between ``origins`` and ``distance`` along unit ``directions``."""
    t = surfaces.cast(origins, directions).t.double()
    return t >= distance.to(t.device) * (1.0 - 1e-6) - SURFACE_OFFSET


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
        visible = _visible(surfaces, *(torch.from_numpy(a) for a in (origins, direction, distance)))
        lit = (geometry > 0) & visible.cpu().numpy()
        irradiance += (emitters.area_radiance[chosen] * (geometry * lit)[:, None]) / light_samples
    return irradiance


class DeltaLights:
    """The scene's lights of no extent (point and spot lights, directional suns) as tensors on one
    device, and the exact irradiance they give, one shadow ray each: the renderer shades it per hit
    and the bake carries only its bounces.

    Args:
        emitters: the scene's emitters.
        device: where the shading runs.
    """

    def __init__(self, emitters: Emitters, device: torch.device | str = "cpu") -> None:
        def table(values: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.asarray(values, np.float64).reshape(-1, 3)).to(device)

        self.positions, self.intensity = table(emitters.point_positions), table(emitters.point_intensity)
        self.spot_axes = table(emitters.spot_directions)
        # per light, what the spot's falloff needs (None: a point light), known when the scene is read
        self.spots = [
            (float(np.arccos(beam)), float(np.arccos(cutoff))) if cutoff > -1.0 else None
            for beam, cutoff in zip(emitters.spot_cos_beam, emitters.spot_cos_cutoff)
        ]
        self.sun_directions, self.sun_irradiance = table(emitters.sun_directions), table(emitters.sun_irradiance)

    @property
    def empty(self) -> bool:
        return not (len(self.positions) or len(self.sun_directions))

    def irradiance(self, surfaces: Surfaces, points: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
        """(N, 3) float64 irradiance at surface points (N, 3) with unit normals (N, 3), both float64."""
        irradiance = torch.zeros_like(points)
        origins = points + SURFACE_OFFSET * normals
        for index, spot in enumerate(self.spots):
            offset = self.positions[index] - origins
            distance = offset.norm(dim=1)
            direction = offset / distance.clamp_min(1e-12)[:, None]
            cosine = dot(direction, normals).clamp_min(0.0)
            if spot is not None:
                beam, cutoff = spot
                angle = torch.arccos((-direction @ self.spot_axes[index]).clamp(-1.0, 1.0))
                cosine = cosine * ((cutoff - angle) / max(cutoff - beam, 1e-9)).clamp(0.0, 1.0)
            lit = (cosine > 0) & _visible(surfaces, origins, direction, distance)
            irradiance += self.intensity[index] * (cosine * lit / distance.clamp_min(1e-3) ** 2)[:, None]
        for direction, sun in zip(self.sun_directions, self.sun_irradiance):
            cosine = dot(normals, direction)
            lit = (cosine > 0) & ~surfaces.cast(origins, direction.expand_as(origins)).hit
            irradiance += sun * (cosine.clamp_min(0.0) * lit)[:, None]
        return irradiance
