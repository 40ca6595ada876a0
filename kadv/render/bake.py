"""The bake of diffuse global illumination: a Monte-Carlo estimate of irradiance, computed once per
scene and cached; shading looks it up per hit (:mod:`kadv.render.irradiance`).

The bake path-traces with the renderer's own surfaces and ray casters
(:class:`~kadv.render.surface.Surfaces`). Irradiance is stored on a lattice of barycentric points
per triangle and side (a refined mesh that keeps the triangles: triangle ids, depth and silhouettes
stay those of the scene), ``r`` steps along each edge with ``r`` set by the
triangle's size (``texel``), or one point at the centroid for triangles smaller than a texel. In a
scene of so many triangles that those points alone would take half of ``max_points`` (a kitchen's
appliances and plants: a million), the small triangles whose centroids share a texel-sized cell and
whose normals point along one axis the same way share one point, so that the texel need not grow.

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

import numpy as np
import torch
from filelock import FileLock
from scipy.spatial import cKDTree
from tqdm import tqdm

from kadv.device import free_memory
from kadv.io import atomic_write
from kadv.render.colour import LUMINANCE, exposed
from kadv.render.irradiance import BakedLighting, lattice_counts, lattice_ij, nearest_tap
from kadv.render.lights import SURFACE_OFFSET, DeltaLights, Sky, area_irradiance, scene_lights
from kadv.render.surface import RayHits, Surfaces
from kadv.scenes.emitters import DEFAULT_CEILING_LIGHT_SIZE, DEFAULT_LAMP_RADIANCE, MISSING_ENVMAP_RADIANCE, Emitters
from kadv.scenes.scene import Scene

__all__ = ["BakeConfig", "bake_bytes", "bake_lighting", "default_emitters", "load_or_bake"]

_BAKE_VERSION = 12  # part of the cache key: raise it when the bake's arithmetic or its file changes
_SLIVER = 8.0
_CLOSED_ESCAPE_SHARE = 1e-3  # a room whose meter rays escape less than this sees no sky
# a lattice point whose gather rays meet surfaces' hidden sides this often sits in a crevice or at a
# seam: its own estimate is discarded and filled from neighbours
_BURIED_SHARE = 0.25
# gather rays from the free space that must meet a lattice point for its side to join it, per 64
# gather rays a point casts (and at least this many): one ray through a seam's crack does not carry
# the flood beyond a wall. The rays through a crack grow with the rays cast, so the count must too:
# at 256 rays a fixed 2 let the dining room's floor see the sky through the crack under a wall
_FLOOD_HITS = 2
# bytes of one block of the bake's per-point work (its (points, neighbours or rays, 3) intermediates)
_BLOCK_BYTES = 64 * 2**20


@dataclass(frozen=True)
class BakeConfig:
    """Settings of the lighting bake (``render.bake.*``).

    Attributes:
        texel: metres between lattice points on large triangles.
        max_subdivision: the most lattice steps along a triangle's edge.
        max_points: the most lattice points (both sides); ``texel`` grows until the scene fits
            (small triangles share points where one each would take half of them).
        rays: gather rays per lattice point.
        light_samples: shadow rays per lattice point towards the area emitters.
        bounces: diffuse inter-reflections after the direct light.
        neighbours: lattice points the noise filter averages.
        filter_width: the noise filter's Gaussian width, in lattice spacings.
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
    filter_width: float = 3.0
    key: float = 0.18
    seed: int = 0
    cache: str | None = None

    def __post_init__(self) -> None:
        positive = {"texel": self.texel, "filter_width": self.filter_width, "key": self.key}
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
    centroids = corners.mean(axis=1)
    # where one point per small triangle would take half the points (a million-triangle kitchen),
    # small triangles facing one way in one texel-sized cell share a point: else the texel grows
    # until every large floor and wall is one point too
    sharing = 2 * len(size) > config.max_points // 2
    texel = config.texel
    while True:
        resolution = np.where(size < texel, 0, np.minimum(np.ceil(size / texel), config.max_subdivision)).astype(
            np.int64
        )
        small = np.flatnonzero(resolution == 0) if sharing else np.empty(0, np.int64)
        cell, representatives = _shared_cells(centroids[small], scene.face_normals[small], size[small], texel)
        own = np.ones(len(size), bool)
        own[small] = False
        counts = np.where(own, lattice_counts(resolution), 0)
        if 2 * (counts.sum() + len(representatives)) <= config.max_points or texel > 1e3:
            break
        texel *= 1.25
    starts = np.r_[0, np.cumsum(counts)[:-1]]
    per_side = int(counts.sum()) + len(representatives)
    starts[small] = int(counts.sum()) + cell
    triangle_ids, bary = _lattice_points(resolution, own, starts, per_side)
    triangle_ids[int(counts.sum()) :] = small[representatives]
    bary[int(counts.sum()) :] = 1.0 / 3.0
    tri = corners[triangle_ids]
    weights = np.c_[1.0 - bary.sum(axis=1), bary]
    points = np.einsum("nk,nkd->nd", weights, tri)
    # kept a few millimetres inside their triangle: a point on an edge where a wall meets the floor
    # would cast its rays from the seam, through which they leak out of the room
    centroid = tri.mean(axis=1)
    inward = centroid - points
    distance = np.linalg.norm(inward, axis=1, keepdims=True)
    points = points + inward * np.minimum(1.0, SURFACE_OFFSET / np.maximum(distance, 1e-12))
    face_normals, normals = _lattice_normals(scene, triangle_ids, weights)
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


def _lattice_points(
    resolution: np.ndarray, own: np.ndarray, starts: np.ndarray, per_side: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each lattice point's triangle (P,) and barycentric coordinates (P, 2), for the triangles
    with points of their ``own`` (``resolution`` steps along an edge; 0: the centroid alone), from
    each one's first point ``starts``; the shared cells' points are left to fill."""
    triangle_ids = np.empty(per_side, np.int64)
    bary = np.empty((per_side, 2))
    for r in np.unique(resolution[own]):
        faces = np.flatnonzero(own & (resolution == r))
        if r == 0:
            steps = np.full((1, 2), 1.0 / 3.0)
        else:
            i, j = lattice_ij(int(r))
            steps = np.stack([i, j], axis=1) / r
        index = (starts[faces][:, None] + np.arange(len(steps))[None]).reshape(-1)
        triangle_ids[index] = np.repeat(faces, len(steps))
        bary[index] = np.tile(steps, (len(faces), 1))
    return triangle_ids, bary


def _lattice_normals(scene: Scene, triangle_ids: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lattice points' face normals and unit shading normals (P, 3), float64, the latter
    interpolated with the barycentric ``weights`` (P, 3) and turned to the face normal's side."""
    face_normals = scene.face_normals[triangle_ids].astype(np.float64)
    # a degenerate triangle has no normal: any unit vector serves, its area being nil
    face_normals[np.linalg.norm(face_normals, axis=1) < 0.5] = (0.0, 1.0, 0.0)
    normals = np.einsum("nk,nkd->nd", weights, scene.normals[triangle_ids].astype(np.float64))
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    # corner normals that cancel out: the face normal
    normals = np.where(length > 1e-6, normals / np.maximum(length, 1e-12), face_normals)
    # shading normals on the face normal's side (files flip some)
    normals *= np.where(np.einsum("nd,nd->n", normals, face_normals) < 0, -1.0, 1.0)[:, None]
    return face_normals, normals


def _shared_cells(
    centroids: np.ndarray, face_normals: np.ndarray, size: np.ndarray, cell: float
) -> tuple[np.ndarray, np.ndarray]:
    """Small triangles grouped by the ``cell``-metre grid cell of their centroids (M, 3) and the axis
    and sign their face normals (M, 3) point along most: each one's group (M,), and each group's
    largest triangle by ``size`` (M,) (G,), whose centroid stands for the group."""
    if not len(centroids):
        return np.empty(0, np.int64), np.empty(0, np.int64)
    axis = np.abs(face_normals).argmax(axis=1)
    sign = np.take_along_axis(face_normals, axis[:, None], axis=1)[:, 0] > 0
    keys = np.c_[np.floor(centroids / cell).astype(np.int64), 2 * axis + sign]
    order = np.argsort(-size, kind="stable")
    _, first, group = np.unique(keys[order], axis=0, return_index=True, return_inverse=True)
    cells = np.empty(len(keys), np.int64)
    cells[order] = group.reshape(-1)
    return cells, order[first]


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


def default_emitters(scene: Scene, escape_share: float) -> Emitters:
    """The emitters of a scene whose file has none: a uniform sky through its openings, and where
    the room is closed (``escape_share`` of rays from its cameras leave it) a square ceiling light,
    facing down, at each of the direct shading's lights."""
    emitters = Emitters(sky_radiance=np.full(3, MISSING_ENVMAP_RADIANCE), defaulted=True)
    if escape_share >= _CLOSED_ESCAPE_SHARE:
        return emitters
    half = DEFAULT_CEILING_LIGHT_SIZE / 2
    # two triangles wound so that their normal, the side they emit to, points down
    square = half * np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, -1], [1, 0, 1], [-1, 0, 1]], np.float64)
    for position in scene_lights(scene):
        emitters = emitters.area((position + square).reshape(2, 3, 3), DEFAULT_LAMP_RADIANCE)
    return emitters


def _meter(surfaces: Surfaces, rng: np.random.Generator, count: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """Rays from where the scene's cameras stand (its file cameras, else its camera region's centre),
    in uniform directions: their origins and directions (N, 3)."""
    scene = surfaces.scene
    if scene.cameras:
        eyes = np.stack([camera.world_T_cam.numpy()[:3, 3] for camera in scene.cameras])
    else:
        eyes = scene.camera_region.mean(axis=0, keepdims=True)
    directions = rng.normal(size=(len(eyes), count, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    return np.repeat(eyes, count, axis=0), directions.reshape(-1, 3)


def _nearest(lattice: _Lattice, surfaces: Surfaces, hits: RayHits, directions: np.ndarray) -> np.ndarray:
    """(N,) the lattice point nearest each hit (-1 on a miss), on the side the ray arrived from."""
    nearest = nearest_tap(
        torch.from_numpy(lattice.resolution),
        torch.from_numpy(lattice.offsets),
        hits.triangle_ids.clamp_min(0).cpu(),
        hits.barycentrics.double().cpu(),
        surfaces.back_facing(hits, directions).cpu(),
    )
    return torch.where(hits.hit.cpu(), nearest, -1).numpy()


def _blocks(count: int, width: int) -> Iterator[slice]:
    """Row blocks of (count, width, 3) float64 intermediates of about _BLOCK_BYTES each: the bake's
    per-point work in blocks, so that its memory does not grow with points x neighbours or rays."""
    step = max(1, _BLOCK_BYTES // (24 * max(width, 1)))
    for start in range(0, count, step):
        yield slice(start, start + step)


def _filter_weights(
    lattice: _Lattice, neighbours: int, width: float, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour indices and normalised weights (N, k) of the noise filter: nearby ``valid`` points
    facing the same way on the same plane (within a few millimetres), by a Gaussian of their
    distance in units of ``width`` lattice spacings. A point with no valid neighbour (a small part
    buried whole, as an ornament against a wall) averages its neighbours' own estimates instead."""
    # each point's twin on the other side shares its position, and at most one of the two faces a
    # point's way: the tree holds one side, and each neighbour found is taken on the side it faces
    per_side = len(lattice.points) // 2
    count, k = len(lattice.points), min(neighbours, per_side)
    tree = cKDTree(lattice.points[:per_side])
    index = np.empty((count, k), np.int32)  # lattices hold far fewer than 2**31 points
    weights = np.empty((count, k), np.float32)
    for rows in _blocks(count, k):
        points = lattice.points[rows]
        distance, near_index = tree.query(points, k=k, workers=-1)
        near_index = near_index.reshape(len(points), k)
        distance = distance.reshape(len(points), k)
        normals = lattice.face_normals[rows]
        alignment = np.einsum("nd,nkd->nk", normals, lattice.face_normals[near_index])
        near_index = np.where(alignment < 0, near_index + per_side, near_index)
        facing = np.abs(alignment) > 0.9
        plane = np.abs(np.einsum("nd,nkd->nk", normals, lattice.points[near_index] - points[:, None]))
        near = (
            np.exp(-((distance / (width * lattice.spacing[rows, None])) ** 2)) * facing * (plane < 4 * SURFACE_OFFSET)
        )
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


def _free(
    lattice: _Lattice, surfaces: Surfaces, hit_point: np.ndarray, seen: np.ndarray, eyes: np.ndarray
) -> np.ndarray:
    """(N,) whether each lattice point faces the free space the cameras stand in: a flood fill over
    the gather rays (``hit_point`` (N, rays): the lattice point each met, -1 on a miss) from the
    points that rays from the cameras meet (``seen`` (M,), the rays from ``eyes`` (M, 3)).

    A ray meets a lattice point on the side it arrives from, so the fill does not cross a surface:
    the insides of closed meshes (a desk, a window frame) and a wall's rim beyond the wall it meets
    stay out, whatever the windings (files leave them to chance on two-sided materials). A point
    joins once ``_FLOOD_HITS`` rays per 64 from the free space met it and it sees where one of them came
    from: a lattice point stands for a patch, and a ray that meets the floor beside a box would
    otherwise carry the fill to the point under the box that lies nearest."""
    count, rays = hit_point.shape
    needed = max(_FLOOD_HITS, math.ceil(_FLOOD_HITS * rays / 64))
    origin = lambda index: lattice.points[index] + SURFACE_OFFSET * lattice.normals[index]
    free, met = np.zeros(count, bool), np.zeros(count, np.int64)
    # where a ray that met the point came from: a lattice point's index, or -1 - the eye's index
    source = np.zeros(count, np.int32)
    renewed = np.zeros(count, bool)  # whose source changed since its last check
    met_by_eye = np.flatnonzero(seen >= 0)
    met[seen[met_by_eye]] = needed  # a camera sees them: as if enough rays met them
    source[seen[met_by_eye]] = -1 - met_by_eye
    renewed[seen[met_by_eye]] = True
    while True:
        check = np.flatnonzero(renewed & ~free & (met >= needed))
        renewed[:] = False
        if not len(check):
            return free
        sees = np.empty(len(check), bool)
        for rows in _blocks(len(check), 8):  # the positions and rays of a block, not of every point at once
            came_from = source[check[rows]]
            targets = np.where(
                (came_from >= 0)[:, None], origin(np.maximum(came_from, 0)), eyes[np.maximum(-1 - came_from, 0)]
            )
            sees[rows] = _sees(surfaces, origin(check[rows]), targets)
        joined = check[sees]
        free[joined] = True
        for rows in _blocks(len(joined), rays):
            block = hit_point[joined[rows]]
            reached = block >= 0
            met += np.bincount(block[reached], minlength=count)
            source[block[reached]] = np.repeat(joined[rows], rays)[reached.reshape(-1)]
            renewed[block[reached]] = True


def _sees(surfaces: Surfaces, origins: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(N,) whether nothing lies between each of ``origins`` (N, 3) and its target (N, 3)."""
    offset = targets - origins
    length = np.linalg.norm(offset, axis=1)
    directions = offset / np.maximum(length, 1e-12)[:, None]
    distance = surfaces.cast(origins, directions).t.double().cpu().numpy()
    # a tenth of a millimetre for float32's rounding: a point at a box's edge may sit that little
    # outside the face it meets, and a looser check lets the fill through the edge
    return distance >= length - 1e-4


def _buried(hit_point: np.ndarray, free: np.ndarray) -> np.ndarray:
    """(N,) whether each lattice point's own estimate is discarded: it does not face the free space
    (:func:`_free`), or more than ``_BURIED_SHARE`` of its gather rays meet sides that do not (a
    point in a crevice or at a seam, whose rays leave the room through the crack)."""
    buried = ~free
    for rows in _blocks(len(hit_point), hit_point.shape[1]):
        block = hit_point[rows]
        hidden = (block >= 0) & ~free[np.maximum(block, 0)]
        buried[rows] |= hidden.mean(axis=1) > _BURIED_SHARE
    return buried


def _albedo(surfaces: Surfaces, lattice: _Lattice) -> np.ndarray:
    """(N, 3) linear albedo at the lattice points, textures filtered to the lattice's spacing."""
    ids = torch.from_numpy(lattice.triangle_ids).to(surfaces.device)
    bary = torch.from_numpy(lattice.bary).to(surfaces.device)
    footprint = torch.full((len(ids),), float(lattice.texel), dtype=torch.float32, device=surfaces.device)
    base = surfaces.albedo(ids, bary, footprint)
    return surfaces.reflectance(ids, base).double().cpu().numpy()


def bake_bytes(points: int, config: BakeConfig) -> int:
    """About the most memory a bake of ``points`` lattice points takes: per point its arrays (position,
    normals, sums of light: about 400 bytes), its gather rays' hits (4 bytes a ray) and its filter's
    neighbours (8 bytes each), then the blocks of per-point work and the renderer beside them."""
    per_point = 400 + 4 * config.rays + 8 * config.neighbours
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


def bake_lighting(surfaces: Surfaces, config: BakeConfig | None = None, progress: bool = True) -> BakedLighting:
    """Bake the diffuse global illumination of ``surfaces``'s scene (no cache: see :func:`load_or_bake`)."""
    config = config or BakeConfig()
    start = time.perf_counter()
    rng = np.random.default_rng(config.seed)
    scene = surfaces.scene
    eyes, meter_directions = _meter(surfaces, rng)
    meter = surfaces.cast(eyes, meter_directions)
    emitters = scene.emitters
    if emitters.empty:
        escape_share = float((~meter.hit).double().mean())
        emitters = default_emitters(scene, escape_share)
    lattice = _build_lattice(scene, config)
    count = len(lattice.points)
    _check_fits(scene.name, count, config)
    albedo = _albedo(surfaces, lattice)
    direct = np.zeros((count, 3))
    delta = np.zeros((count, 3))
    sky = np.zeros((count, 3))
    hit_point = np.empty((count, config.rays), np.int32)
    sky_along, delta_lights = Sky(emitters), DeltaLights(emitters, surfaces.device)
    chunk = max(1, 2_000_000 // config.rays)
    steps = range(0, count, chunk)
    for begin in tqdm(steps, desc=f"baking {scene.name}", unit="chunk", disable=not progress, leave=False):
        end = min(begin + chunk, count)
        points, normals = lattice.points[begin:end], lattice.normals[begin:end]
        direct[begin:end] = area_irradiance(surfaces, emitters, points, normals, rng, config.light_samples)
        on_device = (torch.from_numpy(a).to(surfaces.device) for a in (points, normals))
        delta[begin:end] = delta_lights.irradiance(surfaces, *on_device).cpu().numpy()
        directions = _cosine_directions(normals, rng, config.rays).reshape(-1, 3)
        origins = np.repeat(points + SURFACE_OFFSET * normals, config.rays, axis=0)
        hits = surfaces.cast(origins, directions)
        escaped = ~hits.hit.cpu().numpy()
        sky_seen = np.where(escaped[:, None], sky_along(torch.from_numpy(directions)).numpy(), 0.0)
        sky[begin:end] = np.pi * sky_seen.reshape(end - begin, config.rays, 3).mean(axis=1)
        nearest = _nearest(lattice, surfaces, hits, directions)
        hit_point[begin:end] = nearest.reshape(end - begin, config.rays)
    seen = _nearest(lattice, surfaces, meter, meter_directions)
    free = _free(lattice, surfaces, hit_point, seen, eyes)
    buried = _buried(hit_point, free)
    index, weights = _filter_weights(lattice, config.neighbours, config.filter_width, ~buried)
    smooth = lambda values: _smooth(index, weights, values)
    # the delta lights' own term is shaded per hit, with sharp shadows (a lattice point may stand
    # metres apart on a large floor); the light they bounce is baked
    delta = smooth(delta)
    baked = _bounced(smooth, direct + sky, delta, albedo, hit_point, config.bounces)
    return BakedLighting(
        resolution=lattice.resolution,
        offsets=lattice.offsets,
        irradiance=baked.astype(np.float32),
        exposure=_exposure(seen[seen >= 0], albedo, baked + delta, config.key),
        buried=buried,
        enclosed=~free,
        seconds=time.perf_counter() - start,
    )


def _bounced(smooth, emitted: np.ndarray, delta: np.ndarray, albedo: np.ndarray, hit_point: np.ndarray,
             bounces: int) -> np.ndarray:  # fmt: skip
    """The baked irradiance (N, 3): the smoothed light arriving straight from the emitters and the
    sky (``emitted``), then ``bounces`` diffuse inter-reflections, each gathering what the points
    that each point's rays hit (``hit_point``) leave, the delta lights' own term (``delta``) included."""
    baked = smooth(emitted)
    for _ in range(bounces):
        leaving = np.concatenate([albedo * (baked + delta), np.zeros((1, 3))])  # pi x outgoing radiance
        baked = smooth(emitted + _gather(leaving, hit_point))
    return baked


def _exposure(seen: np.ndarray, albedo: np.ndarray, irradiance: np.ndarray, key: float) -> float:
    """The exposure that maps the median radiance the scene's cameras see (at the lattice points
    ``seen``) to the key grey."""
    radiance = (albedo[seen] * irradiance[seen] / np.pi) @ LUMINANCE if len(seen) else np.zeros(1)
    median = float(np.median(radiance))
    return exposed(key) / median if median > 0 else 1.0


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
            buried=data["buried"],
            enclosed=data["enclosed"],
        )
    counts = lattice_counts(baked.resolution)
    if (
        baked.resolution.shape != (num_triangles,)
        or baked.offsets.shape != (2, num_triangles)
        or baked.irradiance.ndim != 2
        or baked.irradiance.shape[1] != 3
        or baked.offsets.min(initial=0) < 0
        or (baked.offsets + counts).max(initial=0) > len(baked.irradiance)
        or baked.buried.shape != baked.irradiance.shape[:1]
        or baked.enclosed.shape != baked.irradiance.shape[:1]
        or not np.isfinite(baked.irradiance).all()
        or not (np.isfinite(baked.exposure) and baked.exposure > 0)
    ):
        raise ValueError("its arrays do not fit the scene")
    return baked


def load_or_bake(surfaces: Surfaces, config: BakeConfig | None = None, progress: bool = True) -> BakedLighting:
    """The scene's baked lighting from the cache, else baked now and cached (written atomically).

    A cache file that cannot be read, or does not fit, is moved aside with a warning and baked again.
    Each cache entry is locked while it is read or baked: a second process that needs the same bake
    (a sweep's jobs on one scene) waits for the first and reads its result instead of baking again.
    """
    config = config or BakeConfig()
    digest = _scene_digest(surfaces.scene, config)
    path = config.cache_dir() / f"{surfaces.scene.name}-{digest[:24]}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    with FileLock(path.with_name(path.name + ".lock")):
        return _load_or_bake(surfaces, config, progress, path, digest)


def _load_or_bake(surfaces: Surfaces, config: BakeConfig, progress: bool, path: Path, digest: str) -> BakedLighting:
    if path.exists():
        try:
            return _read(path, digest, surfaces.scene.num_triangles)
        except Exception as error:  # a damaged file raises many kinds (zip, pickle, key, value)
            aside = path.with_name(path.name + ".corrupt")
            os.replace(path, aside)
            warnings.warn(
                f"lighting cache {path} is unreadable ({type(error).__name__}: {error}); "
                f"moved to {aside} and baked again",
                stacklevel=2,
            )
    baked = bake_lighting(surfaces, config, progress)

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:
            np.savez(
                handle,
                digest=np.array(digest),
                resolution=baked.resolution,
                offsets=baked.offsets,
                irradiance=baked.irradiance,
                exposure=np.array(baked.exposure),
                buried=baked.buried,
                enclosed=baked.enclosed,
            )

    atomic_write(path, write)
    return baked
