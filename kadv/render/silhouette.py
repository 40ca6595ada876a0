"""Differentiable occlusion edges, in the manner of nvdiffrast's ``antialias``.

A backward warp cannot move a silhouette: at an occlusion edge the image derivative is the motion
of the occluder's outline times the jump in value across it. For neighbouring pixels (a, b) across
a depth discontinuity, the crossing t in [0, 1] of the occluder's edge with the segment between
their centres is found (bisection with real rays picks the occluding triangle, then the exact 3-D
crossing of that triangle's edge with the plane of the two pixel rays gives t as a differentiable
function of the pose). The pixel on the far side of the crossing is blended toward its neighbour
by |t - 1/2|, so d(image)/dt = value(a) - value(b): the derivative of the pixels' area coverage.
Horizontal pairs serve edges steeper than 45 degrees and vertical pairs the others, so that each
edge is counted once.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch

from kadv.checks import check_shape
from kadv.geometry.camera import batched_intrinsics
from kadv.geometry.pose import check_world_T_cam
from kadv.geometry.vector import dot, mat_vec
from kadv.render.raycast import ExactRenderer, RenderOutput
from kadv.render.straight_through import straight_through

__all__ = ["EdgePairs", "edge_crossings", "find_edge_pairs", "silhouette_term"]

_BISECTION_STEPS = 6
_MIN_JUMP = 0.005  # relative depth difference below which neighbours are one surface
_CONTINUITY = 0.01  # relative depth gap at the located crossing that makes it an occlusion
_FG_SHARE = 0.5  # share of the way from the foreground's plane to the background's still foreground
_FG_MAX_RATIO = 1.5  # ... and at most this ratio of the foreground plane's depth
_MAX_CROSSING_ERROR = 0.25  # the chosen edge's exact crossing within a quarter segment of the bisection's


@dataclass
class EdgePairs:
    """Occlusion-edge pairs found in exact renders (N pairs).

    Attributes:
        batch: (N,) view index.
        a, b: (N,) flat pixel indices (b is a's right or lower neighbour).
        horizontal: (N,) bool, True for (x, x+1) pairs.
        edge: (N, 2) vertex indices of the occluder's silhouette edge.
        t: (N,) crossing position found by bisection (no gradient).
    """

    batch: np.ndarray
    a: np.ndarray
    b: np.ndarray
    horizontal: np.ndarray
    edge: np.ndarray
    t: np.ndarray


def _rays(K_inv: np.ndarray, batch: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Camera-frame rays (N, 3) with z = 1 through pixel coordinates uv (N, 2)."""
    return mat_vec(K_inv[batch], np.c_[uv, np.ones(len(uv))])


def _planes(renderer: ExactRenderer, ids: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World normals (N, 3) of triangles ``ids`` (N,) and their planes' offsets n . (v0 - c) (N,)
    from the camera centres ``c`` (N, 3)."""
    safe = np.maximum(ids, 0)
    normal = renderer.scene.face_normals[safe].astype(np.float64)
    offset = dot(normal, renderer.scene.vertices[renderer.scene.faces[safe, 0]] - c)
    return normal, offset


def _plane_z(ids: np.ndarray, offset: np.ndarray, normal_dot_ray: np.ndarray) -> np.ndarray:
    """z-depth where rays (z = 1 in the camera) meet the planes of triangles ``ids`` (inf for ids < 0
    or behind the camera), from the planes' offsets and the normals' dot products with the rays."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = offset / normal_dot_ray
    return np.where((ids >= 0) & (z > 0), z, np.inf)


def _plane_depth(renderer: ExactRenderer, ids: np.ndarray, rays_world: np.ndarray, c: np.ndarray) -> np.ndarray:
    """z-depth where camera rays (z = 1, world frame) (N, 3) from ``c`` meet the plane of triangles ``ids``."""
    normal, offset = _planes(renderer, ids, c)
    return _plane_z(ids, offset, dot(normal, rays_world))


# An edge parallel to the plane of the segment's rays (|m . (v1 - v0)| below this) has no crossing.
_PARALLEL = 1e-12
# Image coordinates divide by z; points this close to the camera plane are clamped, not divided by 0.
_MIN_PROJECTED_Z = 1e-9
# A crossing this close past an edge's end, or this close to the camera plane, still counts: float
# rounding must not drop a crossing that lies exactly on a vertex.
_ENDPOINT_SLACK = 1e-6


def edge_crossings(
    vertices_cam: torch.Tensor,
    rays_a: torch.Tensor,
    rays_b: torch.Tensor,
    K: torch.Tensor,
    uv_a: torch.Tensor,
    uv_b: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Crossing t (N,) of edges (N, 2, 3) (camera frame) with the segment a->b, and whether it is genuine."""
    m = torch.linalg.cross(rays_a, rays_b)
    v0, v1 = vertices_cam[:, 0], vertices_cam[:, 1]
    denominator = dot(m, v1 - v0)
    s = -dot(m, v0) / torch.where(denominator.abs() > _PARALLEL, denominator, torch.ones_like(denominator))
    point = v0 + s[:, None] * (v1 - v0)
    projected = (K @ point[..., None])[..., 0]
    uv = projected[:, :2] / projected[:, 2:3].clamp_min(_MIN_PROJECTED_Z)
    direction = uv_b - uv_a
    t = ((uv - uv_a) * direction).sum(-1) / (direction * direction).sum(-1)
    genuine = (
        (denominator.abs() > _PARALLEL)
        & (s >= -_ENDPOINT_SLACK)
        & (s <= 1 + _ENDPOINT_SLACK)
        & (point[:, 2] > _ENDPOINT_SLACK)
    )
    return t, genuine


@dataclass
class _Candidates:
    """Neighbour pairs (N) across a possible occlusion edge: pixel indices, direction and centres,
    camera rays (z = 1) through both centres in the camera and world frames, and their views' poses."""

    batch: np.ndarray
    a: np.ndarray
    b: np.ndarray
    horizontal: np.ndarray
    uv_a: np.ndarray
    uv_b: np.ndarray
    rays_a: np.ndarray
    rays_b: np.ndarray
    world_a: np.ndarray
    world_b: np.ndarray
    R: np.ndarray
    c: np.ndarray

    def subset(self, keep: np.ndarray) -> _Candidates:
        return _Candidates(*(getattr(self, f.name)[keep] for f in fields(self)))

    @staticmethod
    def concatenate(parts: list[_Candidates]) -> _Candidates:
        return _Candidates(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(_Candidates)))


def _candidate_pairs(
    renderer: ExactRenderer, z: np.ndarray, ids: np.ndarray, pose: np.ndarray, K_inv: np.ndarray, horizontal: bool
) -> _Candidates:
    """Neighbours (x, x+1) or (y, y+1) on different triangles whose depths (B, H, W) jump."""
    batch, _, width = z.shape
    za, zb = (z[:, :, :-1], z[:, :, 1:]) if horizontal else (z[:, :-1, :], z[:, 1:, :])
    ia, ib = (ids[:, :, :-1], ids[:, :, 1:]) if horizontal else (ids[:, :-1, :], ids[:, 1:, :])
    near, far = np.minimum(za, zb), np.maximum(za, zb)
    with np.errstate(invalid="ignore"):  # both rays missing: inf - inf
        candidate = (ia != ib) & np.isfinite(near) & (~np.isfinite(far) | ((far - near) > _MIN_JUMP * near))
    bi, yi, xi = np.nonzero(candidate)
    a = yi * width + xi
    uv_a = np.c_[xi + 0.5, yi + 0.5]
    uv_b = uv_a + ([1.0, 0.0] if horizontal else [0.0, 1.0])
    rays_a, rays_b, R = _rays(K_inv, bi, uv_a), _rays(K_inv, bi, uv_b), pose[bi, :3, :3]
    pairs = _Candidates(
        bi,
        a,
        a + (1 if horizontal else width),
        np.full(len(bi), horizontal),
        uv_a,
        uv_b,
        rays_a,
        rays_b,
        mat_vec(R, rays_a),
        mat_vec(R, rays_b),
        R,
        pose[bi, :3, 3],
    )
    flat_ids, flat_z = ids.reshape(batch, -1), z.reshape(batch, -1)
    # Neighbours on one continuous surface (a grazing floor's triangles) are no edge: the plane of
    # either one's triangle, extended to the other's ray, meets it at its depth. Dropping them here
    # spares the bisection most candidates; it would find no occlusion between them either.
    z_a, z_b = flat_z[bi, pairs.a], flat_z[bi, pairs.b]
    with np.errstate(invalid="ignore"):
        b_on_a = np.abs(_plane_depth(renderer, flat_ids[bi, pairs.a], pairs.world_b, pairs.c) - z_b)
        a_on_b = np.abs(_plane_depth(renderer, flat_ids[bi, pairs.b], pairs.world_a, pairs.c) - z_a)
        continuous = (b_on_a <= _CONTINUITY * z_b) & (a_on_b <= _CONTINUITY * z_a)
    return pairs.subset(~continuous)


def _bisect(
    renderer: ExactRenderer, pairs: _Candidates, flat_z: np.ndarray, flat_ids: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bisect each segment a -> b with real rays for where the foreground ends.

    Returns the occluding triangle (N,), whether the depths on the two sides of the final bracket
    differ enough to be an occlusion (N,), and the crossing t in [0, 1] (N,).
    """
    bi = pairs.batch
    a_is_fg = flat_z[bi, pairs.a] <= flat_z[bi, pairs.b]
    fg_id = np.where(a_is_fg, flat_ids[bi, pairs.a], flat_ids[bi, pairs.b])
    bg_id = np.where(a_is_fg, flat_ids[bi, pairs.b], flat_ids[bi, pairs.a])
    lo, hi = np.zeros(len(bi)), np.ones(len(bi))
    id_lo, id_hi = flat_ids[bi, pairs.a].copy(), flat_ids[bi, pairs.b].copy()
    z_lo, z_hi = flat_z[bi, pairs.a].copy(), flat_z[bi, pairs.b].copy()
    # A ray through a point of the segment is affine in the point's position along it, and so are
    # its dot products with the two planes: everything but the cast is computed once.
    world_a, world_step = pairs.world_a, pairs.world_b - pairs.world_a
    (fg_normal, fg_offset), (bg_normal, bg_offset) = (
        _planes(renderer, fg_id, pairs.c),
        _planes(renderer, bg_id, pairs.c),
    )
    fg_a, fg_step = dot(fg_normal, world_a), dot(fg_normal, world_step)
    bg_a, bg_step = dot(bg_normal, world_a), dot(bg_normal, world_step)
    for _ in range(_BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        hits = renderer.cast(pairs.c, world_a + mid[:, None] * world_step).numpy()
        z_fg = _plane_z(fg_id, fg_offset, fg_a + mid * fg_step)
        z_bg = _plane_z(bg_id, bg_offset, bg_a + mid * bg_step)
        # a hit is foreground up to a share of the way to the background's plane, and no further
        # than a bounded ratio beyond the foreground's own plane
        with np.errstate(invalid="ignore", divide="ignore"):  # a plane the ray misses: inf / inf
            limit = z_fg * np.minimum(1.0 + _FG_SHARE * (z_bg / z_fg - 1.0), _FG_MAX_RATIO)
        mid_z = np.where(hits.hit, hits.t, np.inf)
        same_as_a = (hits.hit & (mid_z < limit)) == a_is_fg
        lo, id_lo, z_lo = (
            np.where(same_as_a, mid, lo),
            np.where(same_as_a, hits.triangle_ids, id_lo),
            np.where(same_as_a, mid_z, z_lo),
        )
        hi, id_hi, z_hi = (
            np.where(same_as_a, hi, mid),
            np.where(same_as_a, id_hi, hits.triangle_ids),
            np.where(same_as_a, z_hi, mid_z),
        )
    occluder = np.where(a_is_fg, id_lo, id_hi)
    near_z, far_z = np.minimum(z_lo, z_hi), np.maximum(z_lo, z_hi)
    occlusion = (occluder >= 0) & np.isfinite(near_z) & ((far_z - near_z) > _CONTINUITY * near_z)
    return occluder, occlusion, 0.5 * (lo + hi)


def _occluder_edge(
    renderer: ExactRenderer, pairs: _Candidates, occluder: np.ndarray, t_star: np.ndarray, K: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which of the occluder's three edges crosses the segment at ``t_star``.

    Returns its vertex indices (N, 2), how far (in segment units) its exact crossing lies from
    ``t_star`` (N,), and whether it is steep in the image (N,).
    """
    bi, R, c = pairs.batch, pairs.R, pairs.c
    faces = renderer.scene.faces[np.maximum(occluder, 0)]
    edges = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1)  # (N, 3, 2)
    vertices_cam = mat_vec(R.swapaxes(1, 2), renderer.scene.vertices[edges] - c[:, None, None])
    three = lambda array: torch.from_numpy(np.repeat(array, 3, axis=0))
    t_all, ok_all = edge_crossings(
        torch.from_numpy(vertices_cam.reshape(-1, 2, 3)),
        three(pairs.rays_a),
        three(pairs.rays_b),
        three(K[bi]),
        three(pairs.uv_a),
        three(pairs.uv_b),
    )
    n = len(bi)
    error = np.where(ok_all.numpy(), np.abs(t_all.numpy() - np.repeat(t_star, 3)), np.inf).reshape(n, 3)
    best = error.argmin(axis=1)
    chosen = edges[np.arange(n), best]
    v = renderer.scene.vertices[chosen]
    # image-plane direction of the edge (first order, at the crossing depth)
    direction_cam = mat_vec(R.swapaxes(1, 2), v[:, 1] - v[:, 0])
    return chosen, error[np.arange(n), best], np.abs(direction_cam[:, 1]) >= np.abs(direction_cam[:, 0])


def find_edge_pairs(
    renderer: ExactRenderer, exact: RenderOutput, world_T_cam: torch.Tensor, K: torch.Tensor
) -> EdgePairs:
    """Locate occlusion-edge pairs and their occluding triangle edges in exact renders (no gradient).

    Three steps: candidate neighbours across a depth jump in each direction, a bisection with real
    rays for the occluder and the crossing, and the occluder's edge that crosses there.
    """
    depth = exact.depth[:, 0].double().cpu().numpy()
    ids = exact.triangle_ids[:, 0].cpu().numpy()
    batch = depth.shape[0]
    pose = check_world_T_cam(world_T_cam).detach().double().numpy()
    K = batched_intrinsics(K, batch).numpy()
    K_inv = np.linalg.inv(K)
    z = np.where(depth > 0, depth, np.inf)
    # both directions' candidates in one bisection: its casts are batched
    pairs = _Candidates.concatenate(
        [_candidate_pairs(renderer, z, ids, pose, K_inv, horizontal) for horizontal in (True, False)]
    )
    if not len(pairs.batch):
        empty = np.zeros(0, np.int64)
        return EdgePairs(empty, empty, empty, np.zeros(0, bool), np.zeros((0, 2), np.int64), np.zeros(0))
    occluder, occlusion, t_star = _bisect(renderer, pairs, z.reshape(batch, -1), ids.reshape(batch, -1))
    chosen, error, steep = _occluder_edge(renderer, pairs, occluder, t_star, K)
    keep = occlusion & (error < _MAX_CROSSING_ERROR) & (steep == pairs.horizontal)
    return EdgePairs(
        pairs.batch[keep], pairs.a[keep], pairs.b[keep], pairs.horizontal[keep], chosen[keep], t_star[keep]
    )


def silhouette_term(
    renderer: ExactRenderer, pairs: EdgePairs, world_T_cam: torch.Tensor, K: torch.Tensor, values: torch.Tensor
) -> torch.Tensor:
    """Zero-valued (B, C, H, W) tensor whose gradient is the edge-motion derivative of ``values``.

    Args:
        pairs: from :func:`find_edge_pairs` on the exact render at ``world_T_cam``.
        world_T_cam: (B, 4, 4) current poses, differentiable.
        K: intrinsics (3, 3) or (B, 3, 3).
        values: (B, C, H, W) exact per-pixel values (detached) whose jumps the edges carry; the
            term is built on their device.
    """
    check_shape(world_T_cam, "B 4 4", "world_T_cam", check_shape(values, "B C H W", "values"))
    batch, channels, height, width = values.shape
    device = values.device
    term = torch.zeros(batch * height * width, channels, dtype=torch.float64, device=device)
    if len(pairs.batch) == 0:
        return term.view(batch, height, width, channels).permute(0, 3, 1, 2).to(values.dtype) + (
            0 * world_T_cam.sum()
        ).to(device)
    K = batched_intrinsics(K, batch)
    bi = torch.from_numpy(pairs.batch)
    R, c = world_T_cam[bi, :3, :3].double(), world_T_cam[bi, :3, 3].double()
    vertices = torch.from_numpy(renderer.scene.vertices[pairs.edge])  # (N, 2, 3) world
    vertices_cam = (vertices - c[:, None]) @ R  # R^T (v - c), row-vector form
    ya, xa = np.divmod(pairs.a, width)
    uv_a = torch.from_numpy(np.c_[xa + 0.5, ya + 0.5])
    uv_b = uv_a + torch.from_numpy(np.where(pairs.horizontal[:, None], [[1.0, 0.0]], [[0.0, 1.0]]))
    K_inv = torch.linalg.inv(K[bi])
    rays_a = (K_inv @ torch.cat([uv_a, torch.ones(len(bi), 1, dtype=torch.float64)], 1)[..., None])[..., 0]
    rays_b = (K_inv @ torch.cat([uv_b, torch.ones(len(bi), 1, dtype=torch.float64)], 1)[..., None])[..., 0]
    t, genuine = edge_crossings(vertices_cam, rays_a, rays_b, K[bi], uv_a, uv_b)
    far_b = torch.from_numpy(pairs.t > 0.5)
    # the pixel beyond the crossing's half is partly covered by its neighbour's surface
    coefficient = (torch.where(far_b, t - 0.5, 0.5 - t) * genuine).to(device)
    # per pair on the CPU (the pose algebra), per pixel on the values' device
    flat = values.detach().double().permute(0, 2, 3, 1).reshape(batch, -1, channels)
    bi, far_b = bi.to(device), far_b.to(device)
    va, vb = flat[bi, torch.from_numpy(pairs.a).to(device)], flat[bi, torch.from_numpy(pairs.b).to(device)]
    blend = coefficient[:, None] * torch.where(far_b[:, None], va - vb, vb - va)
    target = bi * height * width + torch.from_numpy(np.where(pairs.t > 0.5, pairs.b, pairs.a)).to(device)
    term = term.index_add(0, target, straight_through(blend))
    return term.view(batch, height, width, channels).permute(0, 3, 1, 2).to(values.dtype)
