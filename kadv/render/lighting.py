"""Baked diffuse global illumination: irradiance computed once per scene, looked up per hit.

The bake path-traces with the renderer's own ray caster. Irradiance is stored on a lattice of
barycentric points per triangle and side (a refined mesh that keeps the triangles: triangle ids,
depth and silhouettes stay those of the scene), ``r`` steps along each edge with ``r`` set by the
triangle's size (``texel``), or one point at the centroid for triangles smaller than a texel.

Per lattice point: direct light with shadow rays (area emitters sampled by area and power, point
and spot lights, directional suns), then ``rays`` cosine-distributed gather rays cast once. A gather
ray that leaves the scene brings the sky (uniform or an environment map); one that hits a surface
brings that surface's outgoing radiance, read from the lattice of the previous bounce, so
``bounces`` inter-reflections cost ``bounces`` gathers over the same rays. Between bounces a
geometry-aware filter (neighbours in 3-D on the same plane with the same orientation) removes the
Monte-Carlo noise without bleeding across walls or onto surfaces a few millimetres apart.

A surface point's colour is then ``tone_map(exposure * albedo * irradiance / pi)``: Lambertian,
view-independent (the reprojection relies on it), with one exposure per scene metered from its
cameras.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
import warnings
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from filelock import FileLock
from kornia.color import linear_rgb_to_rgb, rgb_to_linear_rgb
from scipy.spatial import cKDTree
from tqdm import tqdm

from kadv.device import free_memory
from kadv.io import atomic_write
from kadv.scenes.emitters import DEFAULT_CEILING_LIGHT_SIZE, DEFAULT_LAMP_RADIANCE, MISSING_ENVMAP_RADIANCE, Emitters
from kadv.scenes.scene import Scene

if TYPE_CHECKING:
    from kadv.render.raycast import ExactRenderer

__all__ = [
    "BakeConfig",
    "BakedLighting",
    "bake_bytes",
    "bake_lighting",
    "coat_table",
    "coated_albedo",
    "default_emitters",
    "delta_irradiance",
    "exposed",
    "fresnel_diffuse_reflectance",
    "lattice_taps",
    "load_or_bake",
    "sky_emitters",
    "sky_radiance",
    "srgb_decode",
    "tone_map",
]

_BAKE_VERSION = 7  # part of the cache key: raise it when the bake's arithmetic changes
_OFFSET = 1e-3  # metres: ray origins leave the surface by this much, and keep as far from its edges
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
_SLIVER = 8.0
_CLOSED_ESCAPE_SHARE = 1e-3  # a room whose meter rays escape less than this sees no sky
# a lattice point whose gather rays meet the back of surfaces this often lies inside geometry or
# beyond a seam (an overlapping wall's rim): its own estimate is discarded and filled from neighbours
_BURIED_SHARE = 0.25
# bytes of one block of the bake's per-point work (its (points, neighbours or rays, 3) intermediates)
_BLOCK_BYTES = 64 * 2**20


@dataclass(frozen=True)
class BakeConfig:
    """Settings of the lighting bake (``render.bake.*``).

    Attributes:
        texel: metres between lattice points on large triangles.
        max_subdivision: the most lattice steps along a triangle's edge.
        max_points: the most lattice points (both sides); ``texel`` grows until the scene fits.
        rays: gather rays per lattice point.
        light_samples: shadow rays per lattice point towards the area emitters.
        bounces: diffuse inter-reflections after the direct light.
        neighbours: lattice points the noise filter averages.
        key: the linear display grey that the metered median radiance is shown as.
        seed: seed of the Monte-Carlo sampling; the same seed gives the same bake, bit for bit.
        cache: folder of baked files; None: ``$KADV_CACHE/lighting`` or ``~/.cache/kadv/lighting``.
    """

    texel: float = 0.05
    max_subdivision: int = 64
    max_points: int = 1_500_000
    rays: int = 64
    light_samples: int = 32
    bounces: int = 3
    neighbours: int = 32
    key: float = 0.18
    seed: int = 0
    cache: str | None = None

    def __post_init__(self) -> None:
        positive = {"texel": self.texel, "key": self.key}
        for name, value in positive.items():
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise ValueError(f"render.bake.{name} must be a positive number, got {value!r}")
        counts = {
            "max_subdivision": (self.max_subdivision, 1),
            "max_points": (self.max_points, 1),
            "rays": (self.rays, 1),
            "light_samples": (self.light_samples, 1),
            "bounces": (self.bounces, 0),
            "neighbours": (self.neighbours, 1),
            "seed": (self.seed, 0),
        }
        for name, (value, minimum) in counts.items():
            if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
                raise ValueError(f"render.bake.{name} must be an integer >= {minimum}, got {value!r}")

    def cache_dir(self) -> Path:
        if self.cache is not None:
            return Path(self.cache).expanduser()
        root = os.environ.get("KADV_CACHE")
        return (Path(root) if root else Path.home() / ".cache" / "kadv") / "lighting"


@dataclass
class BakedLighting:
    """Irradiance on each triangle's lattice, both sides.

    Attributes:
        resolution: (F,) int64 lattice steps per edge (0: one point at the centroid).
        offsets: (2, F) int64 index of each triangle's first lattice point, front side then back.
        irradiance: (N, 3) float32 linear irradiance at the lattice points.
        exposure: the scene's one scale from radiance to display values.
        seconds: how long the bake took (0 when read from the cache).
    """

    resolution: np.ndarray
    offsets: np.ndarray
    irradiance: np.ndarray
    exposure: float
    seconds: float = 0.0

    def irradiance_at(self, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor) -> torch.Tensor:
        """(N, 3) irradiance at hits: triangle ids (N,), Open3D barycentrics (N, 2) and side (N,) bool."""
        taps, weights = lattice_taps(
            torch.from_numpy(self.resolution), torch.from_numpy(self.offsets), triangle_ids, bary, back
        )
        irradiance = torch.from_numpy(self.irradiance)
        values = irradiance.index_select(0, taps.reshape(-1)).reshape(*taps.shape, 3)
        return (values * weights[..., None].float()).sum(dim=1)


def _channels_last(convert, values: torch.Tensor) -> torch.Tensor:
    """kornia's colour ``convert`` (which takes (*, 3, H, W)) applied to colours (..., 3)."""
    return convert(values.reshape(-1, 3).T[:, :, None])[:, :, 0].T.reshape(values.shape)


def srgb_decode(srgb: torch.Tensor) -> torch.Tensor:
    """Linear values (..., 3) of sRGB-encoded ones in [0, 1]."""
    return _channels_last(rgb_to_linear_rgb, srgb)


def tone_map(linear: torch.Tensor) -> torch.Tensor:
    """Display values (..., 3) in [0, 1] of exposed linear radiance (..., 3): a film-like shoulder ``1 - exp(-x)``
    (linear in the shadows, highlights rolling off rather than clipping, as a camera's response
    does), then sRGB-encoded. The reference comparison tone-maps the path tracer's image the same way."""
    return _channels_last(linear_rgb_to_rgb, -torch.expm1(-linear.clamp_min(0.0)))


def fresnel_diffuse_reflectance(eta: float, samples: int = 4096) -> float:
    """The cosine-weighted hemispherical average of the unpolarised Fresnel reflectance at an
    interface of relative index ``eta`` (below 1: light inside the denser medium, where total
    internal reflection sets in); 0.092 for eta 1.5 and 0.596 for 1 / 1.5."""
    mu = (np.arange(samples) + 0.5) / samples  # cosine of incidence, midpoint rule
    sin_t2 = (1.0 - mu**2) / eta**2
    cos_t = np.sqrt(np.clip(1.0 - sin_t2, 0.0, None))
    rs = (mu - eta * cos_t) / (mu + eta * cos_t)
    rp = (eta * mu - cos_t) / (eta * mu + cos_t)
    reflectance = np.where(sin_t2 >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))
    return float(np.mean(2.0 * mu * reflectance))


def coat_table(scene: Scene) -> np.ndarray:
    """(M, 4) per material: the share of the base's light that its dielectric coat lets out, the
    coat's internal diffuse reflectance, its own reflectance, and 1 where internal scattering
    deepens the base's colour (Mitsuba's ``nonlinear``). A bare material is (1, 0, 0, 0)."""
    table = np.tile([1.0, 0.0, 0.0, 0.0], (len(scene.materials), 1))
    for index, material in enumerate(scene.materials):
        if material.coat_ior is not None:
            outside = fresnel_diffuse_reflectance(material.coat_ior)
            inside = fresnel_diffuse_reflectance(1.0 / material.coat_ior)
            let_out = (1.0 - outside) ** 2 / material.coat_ior**2
            table[index] = (let_out, inside, outside, float(material.coat_nonlinear))
    return table


def coated_albedo(albedo: torch.Tensor, coats: torch.Tensor) -> torch.Tensor:
    """(N, 3) linear albedo, as diffuse light sees it, of bases with linear albedo (N, 3) under
    coats (N, 4) (rows of :func:`coat_table`).

    Mitsuba's plastic with its two Fresnel transmissions averaged over the hemisphere: the base's
    light trapped and re-scattered under the coat, plus the coat's own reflection counted as if it
    were diffuse (its energy bounces on; its view-dependent highlights are not rendered).
    """
    let_out, inside, outside, nonlinear = coats.unbind(dim=1)
    trapped = inside[:, None] * torch.where(nonlinear[:, None] > 0, albedo, torch.ones_like(albedo))
    return let_out[:, None] * albedo / (1.0 - trapped) + outside[:, None]


def exposed(display: float) -> float:
    """The exposed linear radiance that :func:`tone_map` shows as the linear display value ``display``."""
    return -math.log1p(-min(display, 0.999))


def _lattice_ij(r: int) -> tuple[np.ndarray, np.ndarray]:
    """Lattice steps (i, j), i + j <= r, row by row: point k of a triangle of resolution r."""
    i, j = np.triu_indices(r + 1)
    j = j - i
    return i, j


def lattice_taps(
    resolution: torch.Tensor, offsets: torch.Tensor, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The three lattice points (N, 3) around each hit and their weights (N, 3), which sum to 1.

    Args:
        resolution: (F,) lattice steps per triangle.
        offsets: (2, F) first lattice point of each triangle's front and back side.
        triangle_ids: (N,) hit triangles.
        bary: (N, 2) Open3D barycentrics (u, v): the point is (1 - u - v) p0 + u p1 + v p2.
        back: (N,) True on the back side.
    """
    r = resolution.index_select(0, triangle_ids)
    start = offsets[back.long(), triangle_ids]
    rf = r.clamp_min(1).to(bary.dtype)
    uv = bary.clamp_min(0.0)
    uv = uv / uv.sum(dim=1, keepdim=True).clamp_min(1.0)
    a, b = uv[:, 0] * rf, uv[:, 1] * rf
    i0 = torch.minimum(torch.floor(a).long(), r.clamp_min(1) - 1)
    j0 = torch.minimum(torch.floor(b).long(), r.clamp_min(1) - 1 - i0).clamp_min(0)
    fa, fb = a - i0, b - j0
    upper = fa + fb > 1.0
    corner_i = torch.stack([i0, i0 + 1, i0], dim=1) + upper[:, None] * torch.tensor([[1, -1, 1]])
    corner_j = torch.stack([j0, j0, j0 + 1], dim=1) + upper[:, None] * torch.tensor([[1, 1, -1]])
    weights = torch.where(
        upper[:, None],
        torch.stack([fa + fb - 1.0, 1.0 - fa, 1.0 - fb], dim=1),
        torch.stack([1.0 - fa - fb, fa, fb], dim=1),
    ).clamp_min(0.0)
    row_start = corner_i * (r[:, None] + 1) - corner_i * (corner_i - 1) // 2
    taps = start[:, None] + row_start + corner_j
    centroid = r == 0  # one point: every tap is it
    taps = torch.where(centroid[:, None], start[:, None].expand(-1, 3), taps)
    weights = torch.where(centroid[:, None], torch.tensor([1.0, 0.0, 0.0], dtype=weights.dtype), weights)
    return taps, weights / weights.sum(dim=1, keepdim=True)


@dataclass
class _Lattice:
    """Lattice points of every triangle and side: positions, shading normals, triangles, barycentrics."""

    resolution: np.ndarray
    offsets: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    face_normals: np.ndarray
    triangle_ids: np.ndarray
    bary: np.ndarray
    texel: float
    spacing: np.ndarray


def _build_lattice(scene: Scene, config: BakeConfig) -> _Lattice:
    corners = scene.vertices[scene.faces]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    # a triangle's points grow with its area (r^2 / 2 points for r steps), so that long slivers
    # (mouldings, trims) take few; along the longest edge at most _SLIVER texels lie between points
    size = np.maximum(
        np.sqrt(2.0 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)),
        edges / _SLIVER,
    )
    texel = config.texel
    while True:
        resolution = np.where(size < texel, 0, np.minimum(np.ceil(size / texel), config.max_subdivision)).astype(
            np.int64
        )
        counts = (resolution + 1) * (resolution + 2) // 2
        if 2 * counts.sum() <= config.max_points or texel > 1e3:
            break
        texel *= 1.25
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    per_side = int(counts.sum())
    triangle_ids = np.empty(per_side, np.int64)
    bary = np.empty((per_side, 2))
    for r in np.unique(resolution):
        faces = np.flatnonzero(resolution == r)
        if r == 0:
            steps = np.full((1, 2), 1.0 / 3.0)
        else:
            i, j = _lattice_ij(int(r))
            steps = np.stack([i, j], axis=1) / r
        index = (starts[faces][:, None] + np.arange(len(steps))[None]).reshape(-1)
        triangle_ids[index] = np.repeat(faces, len(steps))
        bary[index] = np.tile(steps, (len(faces), 1))
    tri = corners[triangle_ids]
    weights = np.c_[1.0 - bary.sum(axis=1), bary]
    points = np.einsum("nk,nkd->nd", weights, tri)
    # kept a few millimetres inside their triangle: a point on an edge where a wall meets the floor
    # would cast its rays from the seam, through which they leak out of the room
    centroid = tri.mean(axis=1)
    inward = centroid - points
    distance = np.linalg.norm(inward, axis=1, keepdims=True)
    points = points + inward * np.minimum(1.0, _OFFSET / np.maximum(distance, 1e-12))
    face_normals = scene.face_normals[triangle_ids].astype(np.float64)
    # a degenerate triangle has no normal: any unit vector serves, its area being nil
    face_normals[np.linalg.norm(face_normals, axis=1) < 0.5] = (0.0, 1.0, 0.0)
    normals = np.einsum("nk,nkd->nd", weights, scene.normals[triangle_ids].astype(np.float64))
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    # corner normals that cancel out: the face normal
    normals = np.where(length > 1e-6, normals / np.maximum(length, 1e-12), face_normals)
    # shading normals on the face normal's side (files flip some)
    normals *= np.where(np.einsum("nd,nd->n", normals, face_normals) < 0, -1.0, 1.0)[:, None]
    spacing = np.maximum(edges / np.maximum(resolution, 1), texel)[triangle_ids]
    return _Lattice(
        resolution=resolution,
        offsets=np.stack([starts, starts + per_side]),
        points=np.concatenate([points, points]),
        normals=np.concatenate([normals, -normals]),
        face_normals=np.concatenate([face_normals, -face_normals]),
        triangle_ids=np.concatenate([triangle_ids, triangle_ids]),
        bary=np.concatenate([bary, bary]),
        texel=texel,
        spacing=np.concatenate([spacing, spacing]),
    )


def _cosine_directions(normals: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
    """(N, count, 3) cosine-distributed unit directions about unit ``normals`` (N, 3)."""
    u1, u2 = rng.random((2, len(normals), count))
    radius, phi = np.sqrt(u1), 2.0 * np.pi * u2
    local = np.stack([radius * np.cos(phi), radius * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u1))], axis=-1)
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(normals, helper)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(normals, tangent)
    return local[..., :1] * tangent[:, None] + local[..., 1:2] * bitangent[:, None] + local[..., 2:] * normals[:, None]


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


def _visible(renderer: ExactRenderer, origins: np.ndarray, directions: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """(N,) True where nothing lies between ``origins`` and ``distance`` along unit ``directions``."""
    hits = renderer.cast(origins, directions)
    return hits.t >= distance * (1.0 - 1e-6) - _OFFSET


def _area_direct(
    renderer: ExactRenderer, emitters: Emitters, points: np.ndarray, normals: np.ndarray, rng: np.random.Generator,
    light_samples: int,
) -> np.ndarray:  # fmt: skip
    """(N, 3) irradiance from the area emitters, with shadows (``light_samples`` shadow rays each)."""
    irradiance = np.zeros((len(points), 3))
    origins = points + _OFFSET * normals
    triangles = emitters.area_triangles
    if not len(triangles):
        return irradiance
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    light_normals = cross / np.maximum(2.0 * area, 1e-30)[:, None]
    power = area * (emitters.area_radiance @ _LUMINANCE)
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
        lit = (geometry > 0) & _visible(renderer, origins, direction, distance)
        irradiance += (emitters.area_radiance[chosen] * (geometry * lit)[:, None]) / light_samples
    return irradiance


def delta_irradiance(
    renderer: ExactRenderer, emitters: Emitters, points: np.ndarray, normals: np.ndarray
) -> np.ndarray:
    """(N, 3) irradiance at surface points (N, 3) with unit normals (N, 3) from the lights of no
    extent (point and spot lights, directional suns), one shadow ray each: exact, so the renderer
    shades it per hit and the bake carries only its bounces."""
    irradiance = np.zeros((len(points), 3))
    origins = points + _OFFSET * normals
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
        lit = (cosine > 0) & _visible(renderer, origins, direction, distance)
        irradiance += emitters.point_intensity[index] * (cosine * lit / np.maximum(distance, 1e-3) ** 2)[:, None]
    for direction, sun in zip(emitters.sun_directions, emitters.sun_irradiance):
        directions = np.broadcast_to(direction, origins.shape)
        cosine = normals @ direction
        lit = (cosine > 0) & ~renderer.cast(origins, directions).hit
        irradiance += sun * (cosine.clip(0.0) * lit)[:, None]
    return irradiance


def default_emitters(scene: Scene, escape_share: float) -> Emitters:
    """The emitters of a scene whose file has none: a uniform sky through its openings, and where
    the room is closed (``escape_share`` of rays from its cameras leave it) a square ceiling light,
    facing down, at each of the direct shading's lights."""
    from kadv.render.shading import Shading, scene_lights

    emitters = Emitters(sky_radiance=np.full(3, MISSING_ENVMAP_RADIANCE), defaulted=True)
    if escape_share >= _CLOSED_ESCAPE_SHARE:
        return emitters
    half = DEFAULT_CEILING_LIGHT_SIZE / 2
    # two triangles wound so that their normal, the side they emit to, points down
    square = half * np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float64)
    for position in scene_lights(scene, Shading()):
        emitters = emitters.area((position + square).reshape(2, 3, 3), DEFAULT_LAMP_RADIANCE)
    return emitters


def _meter(renderer: ExactRenderer, rng: np.random.Generator, count: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Rays from where the scene's cameras stand (its file cameras, else its camera region's centre),
    in uniform directions: their origins and directions (N, 3)."""
    scene = renderer.scene
    if scene.cameras:
        eyes = np.stack([camera.world_T_cam.numpy()[:3, 3] for camera in scene.cameras])
    else:
        eyes = scene.camera_region.mean(axis=0, keepdims=True)
    directions = rng.normal(size=(len(eyes), count, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    return np.repeat(eyes, count, axis=0), directions.reshape(-1, 3)


def _nearest(lattice: _Lattice, renderer: ExactRenderer, hits, directions: np.ndarray) -> np.ndarray:
    """(N,) the lattice point nearest each hit (-1 on a miss), on the side the ray arrived from."""
    taps, weights = lattice_taps(
        torch.from_numpy(lattice.resolution),
        torch.from_numpy(lattice.offsets),
        torch.from_numpy(np.maximum(hits.triangle_ids, 0)),
        torch.from_numpy(hits.barycentrics),
        torch.from_numpy(renderer.back_facing(hits, directions)),
    )
    nearest = taps.gather(1, weights.argmax(dim=1, keepdim=True))[:, 0].numpy()
    return np.where(hits.hit, nearest, -1)


def _blocks(count: int, width: int) -> Iterator[slice]:
    """Row blocks of (count, width, 3) float64 intermediates of about _BLOCK_BYTES each: the bake's
    per-point work in blocks, so that its memory does not grow with points x neighbours or rays."""
    step = max(1, _BLOCK_BYTES // (24 * max(width, 1)))
    for start in range(0, count, step):
        yield slice(start, start + step)


def _filter_weights(lattice: _Lattice, neighbours: int, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour indices and normalised weights (N, k) of the noise filter: nearby ``valid`` points
    facing the same way on the same plane (within a few millimetres), by a Gaussian of their
    distance in units of the lattice spacing. A point with no valid neighbour (a small part
    buried whole, as an ornament against a wall) averages its neighbours' own estimates instead."""
    # twice the neighbours: each point's twin on the other side shares its position
    count = len(lattice.points)
    k = min(2 * neighbours, count)
    tree = cKDTree(lattice.points)
    index = np.empty((count, k), np.int32)  # lattices hold far fewer than 2**31 points
    weights = np.empty((count, k), np.float32)
    for rows in _blocks(count, k):
        points = lattice.points[rows]
        distance, near_index = tree.query(points, k=k, workers=-1)
        near_index = near_index.reshape(len(points), k)
        distance = distance.reshape(len(points), k)
        normals = lattice.face_normals[rows]
        facing = np.einsum("nd,nkd->nk", normals, lattice.face_normals[near_index]) > 0.9
        plane = np.abs(np.einsum("nd,nkd->nk", normals, lattice.points[near_index] - points[:, None]))
        near = np.exp(-((distance / lattice.spacing[rows, None]) ** 2)) * facing * (plane < 4 * _OFFSET)
        block = near * valid[near_index]
        block = np.where(block.sum(axis=1, keepdims=True) > 0, block, near)
        total = block.sum(axis=1, keepdims=True)
        index[rows], weights[rows] = near_index, block / np.where(total > 0, total, 1.0)
    return index, weights


def _smooth(index: np.ndarray, weights: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(N, 3) each point's filtered ``values`` (N, 3): the weighted mean over its neighbours."""
    out = np.empty((len(index), values.shape[1]))
    for rows in _blocks(len(index), index.shape[1]):
        out[rows] = np.einsum("nk,nkc->nc", weights[rows], values[index[rows]])
    return out


def _gather(leaving: np.ndarray, hit_point: np.ndarray) -> np.ndarray:
    """(N, 3) the mean over each point's gather rays (``hit_point`` (N, rays), -1 on a miss) of
    ``leaving`` (N + 1, 3) at the lattice point each met (its last row, zero, for a miss)."""
    out = np.empty((len(hit_point), 3))
    for rows in _blocks(len(hit_point), hit_point.shape[1]):
        met = hit_point[rows]
        out[rows] = leaving[np.where(met < 0, len(leaving) - 1, met)].mean(axis=1)
    return out


def _buried(lattice: _Lattice, hit_point: np.ndarray) -> np.ndarray:
    """(N,) whether each lattice point lies inside geometry or beyond a seam: more than
    ``_BURIED_SHARE`` of its gather rays (``hit_point`` (N, rays): the lattice point each met, -1 on
    a miss) met a triangle on the side from which the fewest rays meet it.

    A triangle's visible side is the side most rays meet, not its winding's front: files leave
    windings to chance on two-sided materials (a wall wound outwards is one surface seen from the
    room), while from a point inside an object or past an overlapping wall's rim most rays meet
    surfaces from behind."""
    per_side = len(lattice.points) // 2
    triangles = len(lattice.resolution)
    # the lattice point a ray met lies on the side the ray arrived from: its index says which
    from_front, from_back = np.zeros(triangles, np.int64), np.zeros(triangles, np.int64)
    for rows in _blocks(len(hit_point), hit_point.shape[1]):
        met = hit_point[rows][hit_point[rows] >= 0]
        from_front += np.bincount(lattice.triangle_ids[met[met < per_side]], minlength=triangles)
        from_back += np.bincount(lattice.triangle_ids[met[met >= per_side]], minlength=triangles)
    back_hidden = from_back <= from_front  # a tie: the winding's front is the visible side
    buried = np.empty(len(hit_point), bool)
    for rows in _blocks(len(hit_point), hit_point.shape[1]):
        block = hit_point[rows]
        met_hidden = (block >= 0) & ((block >= per_side) == back_hidden[lattice.triangle_ids[block]])
        buried[rows] = met_hidden.mean(axis=1) > _BURIED_SHARE
    return buried


def _albedo(renderer: ExactRenderer, lattice: _Lattice) -> np.ndarray:
    """(N, 3) linear albedo at the lattice points, textures filtered to the lattice's spacing."""
    from kadv.render.shading import albedo

    ids = torch.from_numpy(lattice.triangle_ids)
    uv = renderer._interpolate(renderer._uvs, ids, torch.from_numpy(lattice.bary))
    footprint = torch.full((len(ids),), float(lattice.texel), dtype=torch.float32)
    base = albedo(renderer.scene, ids, uv, footprint, renderer._pyramids, renderer._uv_density)
    return renderer.reflectance(ids, base).double().numpy()


def bake_bytes(points: int, config: BakeConfig) -> int:
    """About the most memory a bake of ``points`` lattice points takes: per point its arrays (position,
    normals, sums of light: about 400 bytes), its gather rays' hits (4 bytes a ray) and its filter's
    neighbours (8 bytes each), then the blocks of per-point work and the renderer beside them."""
    per_point = 400 + 4 * config.rays + 8 * 2 * config.neighbours
    return points * per_point + 3 * _BLOCK_BYTES + 2**30


def _check_fits(name: str, points: int, config: BakeConfig) -> None:
    """Refuse, in one line with the figures, a bake that cannot fit in the memory available."""
    needed, free = bake_bytes(points, config), free_memory()
    if needed > free:
        raise ValueError(
            f"scene {name!r}: baking its light needs about {needed / 2**30:.1f} GiB of memory ({points} "
            f"irradiance points) and {free / 2**30:.1f} GiB are available: lower render.bake.rays or "
            "render.bake.neighbours, or render with render.lighting=direct"
        )


def bake_lighting(renderer: ExactRenderer, config: BakeConfig | None = None, progress: bool = True) -> BakedLighting:
    """Bake the diffuse global illumination of ``renderer``'s scene (no cache: see :func:`load_or_bake`)."""
    config = config or BakeConfig()
    start = time.perf_counter()
    rng = np.random.default_rng(config.seed)
    scene = renderer.scene
    eyes, meter_directions = _meter(renderer, rng)
    emitters = scene.emitters
    if emitters.empty:
        escape_share = float((~renderer.cast(eyes, meter_directions).hit).mean())
        emitters = default_emitters(scene, escape_share)
    lattice = _build_lattice(scene, config)
    count = len(lattice.points)
    _check_fits(scene.name, count, config)
    albedo = _albedo(renderer, lattice)
    direct = np.zeros((count, 3))
    delta = np.zeros((count, 3))
    sky = np.zeros((count, 3))
    hit_point = np.empty((count, config.rays), np.int32)
    chunk = max(1, 2_000_000 // config.rays)
    steps = range(0, count, chunk)
    for begin in tqdm(steps, desc=f"baking {scene.name}", unit="chunk", disable=not progress, leave=False):
        end = min(begin + chunk, count)
        points, normals = lattice.points[begin:end], lattice.normals[begin:end]
        direct[begin:end] = _area_direct(renderer, emitters, points, normals, rng, config.light_samples)
        delta[begin:end] = delta_irradiance(renderer, emitters, points, normals)
        directions = _cosine_directions(normals, rng, config.rays).reshape(-1, 3)
        origins = np.repeat(points + _OFFSET * normals, config.rays, axis=0)
        hits = renderer.cast(origins, directions)
        escaped = ~hits.hit
        sky_seen = np.where(escaped[:, None], sky_radiance(emitters, directions), 0.0)
        sky[begin:end] = np.pi * sky_seen.reshape(end - begin, config.rays, 3).mean(axis=1)
        nearest = _nearest(lattice, renderer, hits, directions)
        hit_point[begin:end] = nearest.reshape(end - begin, config.rays)
    index, weights = _filter_weights(lattice, config.neighbours, ~_buried(lattice, hit_point))
    smooth = lambda values: _smooth(index, weights, values)
    # the delta lights' own term is shaded per hit, with sharp shadows (a lattice point may stand
    # metres apart on a large floor); the light they bounce is baked
    delta = smooth(delta)
    baked = smooth(direct + sky)
    for _ in range(config.bounces):
        leaving = np.concatenate([albedo * (baked + delta), np.zeros((1, 3))])  # pi x outgoing radiance
        baked = smooth(direct + sky + _gather(leaving, hit_point))
    irradiance = baked + delta
    # exposure: the median radiance the scene's cameras see, mapped to the key grey
    meter = renderer.cast(eyes, meter_directions)
    seen = _nearest(lattice, renderer, meter, meter_directions)
    seen = seen[seen >= 0]
    radiance = (albedo[seen] * irradiance[seen] / np.pi) @ _LUMINANCE if len(seen) else np.zeros(1)
    median = float(np.median(radiance))
    exposure = exposed(config.key) / median if median > 0 else 1.0
    return BakedLighting(
        resolution=lattice.resolution,
        offsets=lattice.offsets,
        irradiance=baked.astype(np.float32),
        exposure=exposure,
        seconds=time.perf_counter() - start,
    )


def _scene_digest(scene: Scene, config: BakeConfig) -> str:
    """Hash of everything the bake reads: the loaded scene (the file's content and load options)
    and the bake settings (the cache folder aside)."""
    digest = hashlib.sha256(f"kadv-bake-{_BAKE_VERSION}".encode())
    for array in (scene.vertices, scene.faces, scene.uvs, scene.normals, scene.material_ids, scene.lights):
        digest.update(np.ascontiguousarray(array).tobytes())
    for material in scene.materials:
        fields = (material.name, material.uv_scale.tolist(), material.base_color.tolist())
        digest.update(repr((*fields, material.coat_ior, material.coat_nonlinear)).encode())
        for image in (material.texture, material.opacity):
            digest.update(b"-" if image is None else np.ascontiguousarray(image).tobytes())
    for name, value in asdict(scene.emitters).items():
        digest.update(name.encode() + (b"-" if value is None else np.ascontiguousarray(value).tobytes()))
    for camera in scene.cameras:
        digest.update(camera.world_T_cam.numpy().tobytes())
    settings = {k: v for k, v in asdict(config).items() if k != "cache"}
    digest.update(repr(sorted(settings.items())).encode())
    return digest.hexdigest()


def _read(path: Path, digest: str, num_triangles: int) -> BakedLighting:
    with np.load(path, allow_pickle=False) as data:
        if str(data["digest"]) != digest:
            raise ValueError("it belongs to another scene or settings")
        baked = BakedLighting(
            resolution=data["resolution"],
            offsets=data["offsets"],
            irradiance=data["irradiance"],
            exposure=float(data["exposure"]),
        )
    counts = (baked.resolution + 1) * (baked.resolution + 2) // 2
    if (
        baked.resolution.shape != (num_triangles,)
        or baked.offsets.shape != (2, num_triangles)
        or baked.irradiance.shape != (2 * int(counts.sum()), 3)
        or not np.isfinite(baked.irradiance).all()
        or not (np.isfinite(baked.exposure) and baked.exposure > 0)
    ):
        raise ValueError("its arrays do not fit the scene")
    return baked


def load_or_bake(renderer: ExactRenderer, config: BakeConfig | None = None, progress: bool = True) -> BakedLighting:
    """The scene's baked lighting from the cache, else baked now and cached (written atomically).

    A cache file that cannot be read, or does not fit, is moved aside with a warning and baked again.
    Each cache entry is locked while it is read or baked: a second process that needs the same bake
    (a sweep's jobs on one scene) waits for the first and reads its result instead of baking again.
    """
    config = config or BakeConfig()
    digest = _scene_digest(renderer.scene, config)
    path = config.cache_dir() / f"{renderer.scene.name}-{digest[:24]}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(path.with_name(path.name + ".lock")):
        return _load_or_bake(renderer, config, progress, path, digest)


def _load_or_bake(
    renderer: ExactRenderer, config: BakeConfig, progress: bool, path: Path, digest: str
) -> BakedLighting:
    if path.exists():
        try:
            return _read(path, digest, renderer.scene.num_triangles)
        except Exception as error:  # a damaged file raises many kinds (zip, pickle, key, value)
            aside = path.with_name(path.name + ".corrupt")
            os.replace(path, aside)
            warnings.warn(
                f"lighting cache {path} is unreadable ({type(error).__name__}: {error}); "
                f"moved to {aside} and baked again",
                stacklevel=2,
            )
    baked = bake_lighting(renderer, config, progress)

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:
            np.savez(
                handle,
                digest=np.array(digest),
                resolution=baked.resolution,
                offsets=baked.offsets,
                irradiance=baked.irradiance,
                exposure=np.array(baked.exposure),
            )

    atomic_write(path, write)
    return baked
