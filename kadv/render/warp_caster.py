"""The Warp ray-casting backend: one ``wp.Mesh`` BVH per scene, queried by kernels on CUDA or on
Warp's CPU device, with torch tensors shared in and out without copies (``wp.from_torch``).

Importing this module imports Warp and initialises it; :func:`kadv.render.backends.make_caster`
imports it only when a Warp caster is built. Kernels compile on first use and are cached by Warp
(``wp.config.kernel_cache_dir``, by default ``~/.cache/warp/<version>``).
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import torch
import warp as wp

from kadv.device import free_memory
from kadv.render.casting import AlphaMasks, RayCaster

__all__ = ["WarpCaster"]

wp.config.log_level = wp.LOG_WARNING  # no greeting, no line per module load
wp.init()

# a hit is listed after the previous one when it lies this much further along the ray (relative to
# its t, and at least _MIN_STEP): coincident triangles (t equal to float32 precision) list once
_RELATIVE_STEP = 1e-6
_MIN_STEP = 1e-7
_MAX_HITS = 256  # hits listed per ray at most


@wp.func
def _next_start(t: float):
    return t + wp.max(t * _RELATIVE_STEP, _MIN_STEP)


@wp.kernel
def _walk(
    mesh: wp.uint64,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    fill: int,
    counts: wp.array(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int64),
    ray_ids: wp.array(dtype=wp.int64),
    t: wp.array(dtype=wp.float32),
    ids: wp.array(dtype=wp.int64),
    bary: wp.array(dtype=wp.vec2),
):
    """Walk each ray from hit to hit. With ``fill`` 0, count its hits (at most _MAX_HITS) into
    ``counts``; else write its first ``counts[i]`` hits from slot ``offsets[i]`` on."""
    i = wp.tid()
    limit = _MAX_HITS
    if fill != 0:
        limit = counts[i]
    start = wp.float32(0.0)  # a dynamic variable: the loop updates it
    count = wp.int32(0)
    slot = offsets[i]
    while count < limit:
        query = wp.mesh_query_ray(mesh, origins[i] + directions[i] * start, directions[i], 1.0e30)
        if not query.result:
            break
        if fill != 0:
            ray_ids[slot] = wp.int64(i)
            t[slot] = start + query.t
            ids[slot] = wp.int64(query.face)
            # Warp's (u, v) weigh the triangle's first two corners; Open3D's the last two
            bary[slot] = wp.vec2(query.v, 1.0 - query.u - query.v)
            slot += wp.int64(1)
        count += 1
        start = _next_start(start + query.t)
    if fill == 0:
        counts[i] = count


@wp.func
def _lerp(start: wp.float32, end: wp.float32, weight: wp.float32):
    # torch.lerp's two-sided form, so that a mask reads here as the shading's lookups read it
    if weight < wp.float32(0.5):
        return start + weight * (end - start)
    return end - (end - start) * (wp.float32(1.0) - weight)


@wp.struct
class _Masks:
    """:class:`~kadv.render.casting.AlphaMasks` as kernels read them (shared with its tensors)."""

    slot: wp.array(dtype=wp.int32)
    corner_uvs: wp.array(dtype=wp.vec2d)
    uv_scale: wp.array(dtype=wp.vec2d)
    texels: wp.array(dtype=wp.float32)
    offset: wp.array(dtype=wp.int64)
    height: wp.array(dtype=wp.int64)
    width: wp.array(dtype=wp.int64)
    cutoff: wp.float32


@wp.func
def _opacity(face: wp.int32, u: wp.float32, v: wp.float32, slot: wp.int32, masks: _Masks):
    """Bilinear opacity with wrap-around of mask ``slot`` at Open3D barycentrics (u, v) of ``face``:
    the arithmetic of Surfaces.see_through and TextureAtlas._bilinear, in their precisions."""
    bu = wp.float64(u)
    bv = wp.float64(v)
    uv = masks.corner_uvs[3 * face] * (wp.float64(1.0) - bu - bv) + masks.corner_uvs[3 * face + 1] * bu
    uv = uv + masks.corner_uvs[3 * face + 2] * bv
    scale = masks.uv_scale[slot]
    x_uv = uv[0] * scale[0]
    y_uv = wp.float64(1.0) - uv[1] * scale[1]
    x_uv = x_uv - wp.floor(x_uv)
    y_uv = y_uv - wp.floor(y_uv)
    h = wp.float64(masks.height[slot])
    w = wp.float64(masks.width[slot])
    x = x_uv * w - wp.float64(0.5)
    y = y_uv * h - wp.float64(0.5)
    x0 = wp.floor(x)
    y0 = wp.floor(y)
    fx = wp.float32(x - x0)
    fy = wp.float32(y - y0)
    x1 = x0 + wp.float64(1.0)
    y1 = y0 + wp.float64(1.0)
    if x0 < wp.float64(0.0):
        x0 = x0 + w
    if y0 < wp.float64(0.0):
        y0 = y0 + h
    if x1 >= w:
        x1 = x1 - w
    if y1 >= h:
        y1 = y1 - h
    first = masks.offset[slot]
    top = y0 * w
    bottom = y1 * w
    upper = _lerp(masks.texels[first + wp.int64(top + x0)], masks.texels[first + wp.int64(top + x1)], fx)
    lower = _lerp(masks.texels[first + wp.int64(bottom + x0)], masks.texels[first + wp.int64(bottom + x1)], fx)
    return _lerp(upper, lower, fy)


@wp.kernel
def _walk_opaque(
    mesh: wp.uint64,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    live: wp.array(dtype=wp.int32),
    masks: _Masks,
    t: wp.array(dtype=wp.float32),
    ids: wp.array(dtype=wp.int64),
    bary: wp.array(dtype=wp.vec2),
):
    """Walk each live ray from hit to hit (as _walk lists them) to its first hit on an opaque
    material or an opaque texel of an alpha mask; misses are left as they are."""
    i = wp.tid()
    if live[i] == 0:
        return
    start = wp.float32(0.0)
    count = wp.int32(0)
    while count < _MAX_HITS:
        query = wp.mesh_query_ray(mesh, origins[i] + directions[i] * start, directions[i], 1.0e30)
        if not query.result:
            return
        u = query.v
        v = wp.float32(1.0) - query.u - query.v
        slot = masks.slot[query.face]
        opaque = True
        if slot >= 0:
            opaque = _opacity(query.face, u, v, slot, masks) >= masks.cutoff
        if opaque:
            t[i] = start + query.t
            ids[i] = wp.int64(query.face)
            bary[i] = wp.vec2(u, v)
            return
        count += 1
        start = _next_start(start + query.t)


@wp.kernel
def _closest_points(
    mesh: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    closest: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    query = wp.mesh_query_point_no_sign(mesh, points[i], 1.0e30)
    closest[i] = wp.mesh_eval_position(mesh, query.face, query.u, query.v)


class WarpCaster(RayCaster):
    """Ray queries against a ``wp.Mesh`` BVH on ``device`` (the CPU or a CUDA device)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, device: torch.device) -> None:
        if device.type == "cuda" and device.index is None:  # Warp names CUDA devices by index only
            device = torch.device("cuda", torch.cuda.current_device())
        self.device = device
        self._wp_device = wp.device_from_torch(device)
        self._empty = len(faces) == 0
        self._masks_of: AlphaMasks | None = None
        self._streams: dict[int, wp.Stream] = {}
        if self._empty:
            return
        _check_fits(len(vertices), len(faces), device)
        points = torch.as_tensor(vertices, dtype=torch.float32, device=device).contiguous()
        indices = torch.as_tensor(np.asarray(faces, np.int32).reshape(-1), device=device).contiguous()
        # the mesh keeps its arrays: they must outlive it
        self._points = wp.from_torch(points, dtype=wp.vec3)
        self._indices = wp.from_torch(indices, dtype=wp.int32)
        self.mesh = wp.Mesh(points=self._points, indices=self._indices)
        # the BVH is built on Warp's stream, the casts run on torch's (:meth:`_stream`)
        wp.synchronize_device(self._wp_device)

    def _launch(self, kernel, count: int, inputs: list) -> None:
        """Launch ``kernel`` over ``count`` threads on torch's current stream; torch tensors in
        ``inputs`` are shared with it (no copies)."""
        if count == 0 or self._empty:
            return
        arrays = [_array(x) if isinstance(x, torch.Tensor) else x for x in inputs]
        wp.launch(kernel, dim=count, inputs=[self.mesh.id, *arrays], device=self._wp_device, stream=self._stream())

    def _stream(self) -> wp.Stream | None:
        """Torch's current stream on the caster's CUDA device, as Warp's (None on the CPU). A launch
        goes straight onto it: a ``wp.ScopedStream`` would first make it wait for Warp's own stream,
        a dependency a CUDA graph capture refuses."""
        if self.device.type != "cuda":
            return None
        current = torch.cuda.current_stream(self.device)
        stream = self._streams.get(current.cuda_stream)
        if stream is None:
            stream = self._streams[current.cuda_stream] = wp.stream_from_torch(current)
        return stream

    def _rays(self, *rays: torch.Tensor) -> list[torch.Tensor]:
        return [x.to(self.device, torch.float32).contiguous() for x in rays]

    def first_hits(
        self, origins: torch.Tensor, directions: torch.Tensor, live: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, ...]:
        n = len(origins)
        t, ids, bary = self._misses(n)
        slots = torch.arange(n, device=self.device)
        # hits wanted per ray: one, or none for a dead ray
        limits = self._live(n, live)
        self._launch(_walk, n, [*self._rays(origins, directions), 1, limits, slots, slots.clone(), t, ids, bary])
        return t, ids, bary

    def _misses(self, n: int) -> tuple[torch.Tensor, ...]:
        """t (inf), triangle ids (-1) and barycentrics (0) of ``n`` rays that hit nothing, for a
        kernel to overwrite where they hit."""
        return (
            torch.full((n,), torch.inf, device=self.device),
            torch.full((n,), -1, dtype=torch.int64, device=self.device),
            torch.zeros(n, 2, device=self.device),
        )

    def _live(self, n: int, live: torch.Tensor | None) -> torch.Tensor:
        """(n,) int32: 1 for a ray to cast, 0 for a dead one, whose thread returns at once."""
        return torch.ones(n, dtype=torch.int32, device=self.device) if live is None else live.to(torch.int32)

    applies_alpha_masks = True

    def first_opaque_hits(
        self, origins: torch.Tensor, directions: torch.Tensor, live: torch.Tensor | None, masks: AlphaMasks
    ) -> tuple[torch.Tensor, ...]:
        """In one kernel: each ray walks past the transparent texels it meets to its first opaque hit."""
        n = len(origins)
        t, ids, bary = self._misses(n)
        live = self._live(n, live)
        self._launch(_walk_opaque, n, [*self._rays(origins, directions), live, self._masks(masks), t, ids, bary])
        return t, ids, bary

    def _masks(self, masks: AlphaMasks) -> _Masks:
        """The kernels' view of ``masks``, made on first use (its arrays share the tensors)."""
        if self._masks_of is not masks:
            tables = _Masks()
            for field in fields(AlphaMasks):
                value = getattr(masks, field.name)
                setattr(tables, field.name, _array(value) if isinstance(value, torch.Tensor) else value)
            self._masks_of, self._mask_tables = masks, tables
        return self._mask_tables

    def all_hits(self, origins: torch.Tensor, directions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        n = len(origins)
        rays = self._rays(origins, directions)
        counts = torch.zeros(n, dtype=torch.int32, device=self.device)
        offsets = torch.zeros(n, dtype=torch.int64, device=self.device)
        nothing = [
            torch.zeros(0, dtype=dtype, device=self.device) for dtype in (torch.int64, torch.float32, torch.int64)
        ]
        self._launch(_walk, n, [*rays, 0, counts, offsets, *nothing, torch.zeros(0, 2, device=self.device)])
        offsets = torch.cumsum(counts, 0, dtype=torch.int64) - counts
        total = int(counts.sum())
        ray_ids = torch.empty(total, dtype=torch.int64, device=self.device)
        t = torch.empty(total, device=self.device)
        ids = torch.empty(total, dtype=torch.int64, device=self.device)
        bary = torch.empty(total, 2, device=self.device)
        if total:
            self._launch(_walk, n, [*rays, 1, counts, offsets, ray_ids, t, ids, bary])
        return ray_ids, t, ids, bary

    def closest_points(self, points: torch.Tensor) -> torch.Tensor:
        closest = torch.full((len(points), 3), torch.inf, device=self.device)
        self._launch(_closest_points, len(points), [*self._rays(points), closest])
        return closest


def _check_fits(vertices: int, faces: int, device: torch.device) -> None:
    """Raise a ValueError with the figures when a scene's mesh and BVH would not fit on ``device``."""
    # float32 points, int32 indices, and a BVH of 2F - 1 nodes of two 16-byte halves plus
    # per-primitive bounds and indices, built with the same again in scratch
    needed = 12 * vertices + 12 * faces + 2 * (64 * faces + 28 * faces)
    free = free_memory(device)
    if needed > free:
        raise ValueError(
            f"scene: {faces} triangles need about {needed / 2**20:.0f} MiB of {device} memory for Warp's "
            f"ray-casting BVH, and {free / 2**20:.0f} MiB are free (render.backend=open3d casts on the CPU)"
        )


def _array(x: torch.Tensor) -> wp.array:
    """``x`` as a Warp array without a copy: (N, 3) as vec3 (float64: vec3d), (N, 2) as vec2 (vec2d),
    (N,) as scalars."""
    x = x.contiguous()
    if x.ndim == 2:
        vectors = {torch.float32: {3: wp.vec3, 2: wp.vec2}, torch.float64: {3: wp.vec3d, 2: wp.vec2d}}
        return wp.from_torch(x, dtype=vectors[x.dtype][x.shape[1]])
    return wp.from_torch(x)
