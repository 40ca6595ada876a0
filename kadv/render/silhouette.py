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

import dataclasses
from dataclasses import dataclass, fields

import torch

from kadv.checks import check_shape
from kadv.geometry.camera import batched_intrinsics
from kadv.geometry.pose import check_world_T_cam
from kadv.geometry.vector import dot, mat_vec
from kadv.render.exact import ExactRenderer, RenderOutput
from kadv.render.straight_through import straight_through
from kadv.render.surface import Surfaces

__all__ = ["EdgePairs", "FoundEdges", "edge_crossings", "find_edge_pairs", "silhouette_term", "track_edge_pairs"]

_BISECTION_STEPS = 6
# bisection steps one cast decides (:func:`_bisect`): on a GPU a cast's cost is its launches (three
# steps a cast: a third of them), on the CPU its rays (one step a cast: the fewest)
_STEPS_PER_CAST = {"cpu": 1, "device": 3}
_MIN_JUMP = 0.005  # relative depth difference below which neighbours are one surface
_CONTINUITY = 0.01  # relative depth gap at the located crossing that makes it an occlusion
_FG_SHARE = 0.5  # share of the way from the foreground's plane to the background's still foreground
_FG_MAX_RATIO = 1.5  # ... and at most this ratio of the foreground plane's depth
_MAX_CROSSING_ERROR = 0.25  # the chosen edge's exact crossing within a quarter segment of the bisection's


@dataclass
class EdgePairs:
    """Occlusion-edge pairs found in exact renders (N pairs), tensors on the renderer's device.

    Attributes:
        batch: (N,) int64 view index.
        a, b: (N,) int64 flat pixel indices (b is a's right or lower neighbour).
        horizontal: (N,) bool, True for (x, x+1) pairs.
        edge: (N, 2) int64 vertex indices of the occluder's silhouette edge.
        t: (N,) float64 crossing position found by bisection (no gradient).
        keep: (N,) bool, the pairs that are occlusion edges, where the search kept every neighbour pair
            (on a GPU, which computes them all sooner than it would wait for their count); None: all.
        blocks: where every pair was kept, the pairs per view of each block (horizontal, vertical):
            the pairs are laid out block by block, each view by view; None: compacted.
    """

    batch: torch.Tensor
    a: torch.Tensor
    b: torch.Tensor
    horizontal: torch.Tensor
    edge: torch.Tensor
    t: torch.Tensor
    keep: torch.Tensor | None = None
    blocks: tuple[int, ...] | None = None

    def compacted(self) -> EdgePairs:
        """The pairs that are occlusion edges alone (an uncompacted search's kept ones)."""
        if self.keep is None:
            return self
        return EdgePairs(*(getattr(self, f.name)[self.keep] for f in fields(self) if f.name not in ("keep", "blocks")))

    def to(self, device: torch.device | str) -> EdgePairs:
        return EdgePairs(
            *(v.to(device) if isinstance(v := getattr(self, f.name), torch.Tensor) else v for f in fields(self))
        )


def _rows(table: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``table[index]`` (index of any shape) by ``index_select``: the search's gathers of a few
    thousand rows from tables of hundreds of thousands take a fraction of advanced indexing's time."""
    return table.index_select(0, index.reshape(-1)).reshape(*index.shape, *table.shape[1:])


def _pixels(flat: torch.Tensor, batch: torch.Tensor, pixel: torch.Tensor) -> torch.Tensor:
    """``flat[batch, pixel]`` of per-view pixel values (B, P)."""
    return flat.reshape(-1).index_select(0, batch * flat.shape[1] + pixel)


def _rays(K_inv: torch.Tensor, batch: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    """Camera-frame rays (N, 3) with z = 1 through pixel coordinates uv (N, 2)."""
    return mat_vec(_rows(K_inv, batch), torch.cat([uv, torch.ones_like(uv[:, :1])], dim=1))


def _planes(surfaces: Surfaces, ids: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """World normals (N, 3) of triangles ``ids`` (N,) and their planes' offsets n . (v0 - c) (N,)
    from the camera centres ``c`` (N, 3)."""
    safe = ids.clamp_min(0)
    normal = _rows(surfaces.face_normals, safe)
    offset = dot(normal, _rows(surfaces.vertices, _rows(surfaces.faces[:, 0], safe)) - c)
    return normal, offset


def _plane_z(ids: torch.Tensor, offset: torch.Tensor, normal_dot_ray: torch.Tensor) -> torch.Tensor:
    """z-depth where rays (z = 1 in the camera) meet the planes of triangles ``ids`` (inf for ids < 0
    or behind the camera), from the planes' offsets and the normals' dot products with the rays."""
    z = offset / normal_dot_ray
    return torch.where((ids >= 0) & (z > 0), z, torch.inf)


def _plane_depth(surfaces: Surfaces, ids: torch.Tensor, rays_world: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """z-depth where camera rays (z = 1, world frame) (N, 3) from ``c`` meet the plane of triangles ``ids``."""
    normal, offset = _planes(surfaces, ids, c)
    return _plane_z(ids, offset, dot(normal, rays_world))


# An edge parallel to the plane of the segment's rays (|m . (v1 - v0)| below this) has no crossing.
_PARALLEL = 1e-12
# Image coordinates divide by z; points this close to the camera plane are clamped, not divided by 0.
_MIN_PROJECTED_Z = 1e-9
# A crossing this close past an edge's end, or this close to the camera plane, still counts: float
# rounding must not drop a crossing that lies exactly on a vertex.
_ENDPOINT_SLACK = 1e-6


def _edge_parameter(
    vertices_cam: torch.Tensor, rays_a: torch.Tensor, rays_b: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Where edges (N, 2, 3) (camera frame) meet the plane of the rays a and b (N, 3): the share s
    (N,) of the way from their first vertex, and m . (v1 - v0) (N,), 0 for an edge parallel to it."""
    m = torch.linalg.cross(rays_a, rays_b)
    v0, v1 = vertices_cam[:, 0], vertices_cam[:, 1]
    denominator = dot(m, v1 - v0)
    s = -dot(m, v0) / torch.where(denominator.abs() > _PARALLEL, denominator, torch.ones_like(denominator))
    return s, denominator


def edge_crossings(
    vertices_cam: torch.Tensor,
    rays_a: torch.Tensor,
    rays_b: torch.Tensor,
    K: torch.Tensor,
    uv_a: torch.Tensor,
    uv_b: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Crossing t (N,) of edges (N, 2, 3) (camera frame) with the segment a->b, and whether it is genuine."""
    s, denominator = _edge_parameter(vertices_cam, rays_a, rays_b)
    v0, v1 = vertices_cam[:, 0], vertices_cam[:, 1]
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
    camera rays (z = 1) through both centres in the camera and world frames, their views' poses, and
    whether each is still a candidate (``live``: all True once compacted)."""

    batch: torch.Tensor
    a: torch.Tensor
    b: torch.Tensor
    horizontal: torch.Tensor
    uv_a: torch.Tensor
    uv_b: torch.Tensor
    rays_a: torch.Tensor
    rays_b: torch.Tensor
    world_a: torch.Tensor
    world_b: torch.Tensor
    R: torch.Tensor
    c: torch.Tensor
    live: torch.Tensor

    def subset(self, keep: torch.Tensor, compact: bool) -> _Candidates:
        """The pairs where ``keep`` (N,) is True: compacted (their count read once, not once per
        field), or all of them with ``keep`` marked in :attr:`live`."""
        if not compact:
            return dataclasses.replace(self, live=self.live & keep)
        rows = torch.nonzero(keep)[:, 0]
        return _Candidates(*(getattr(self, f.name).index_select(0, rows) for f in fields(self)))

    @staticmethod
    def concatenate(parts: list[_Candidates]) -> _Candidates:
        return _Candidates(*(torch.cat([getattr(p, f.name) for p in parts]) for f in fields(_Candidates)))


def _jumps(za: torch.Tensor, zb: torch.Tensor, ia: torch.Tensor, ib: torch.Tensor) -> torch.Tensor:
    """Whether neighbours with depths ``za``, ``zb`` (inf: no hit) on triangles ``ia``, ``ib`` may
    straddle an occlusion edge: different triangles and a depth jump."""
    near, far = torch.minimum(za, zb), torch.maximum(za, zb)
    return (ia != ib) & torch.isfinite(near) & (~torch.isfinite(far) | ((far - near) > _MIN_JUMP * near))


def _candidate_pairs(
    surfaces: Surfaces,
    z: torch.Tensor,
    ids: torch.Tensor,
    pose: torch.Tensor,
    K_inv: torch.Tensor,
    horizontal: bool,
    compact: bool,
) -> _Candidates:
    """Neighbours (x, x+1) or (y, y+1) on different triangles whose depths (B, H, W) jump: compacted,
    or every neighbour pair with the candidates marked live."""
    batch, _, width = z.shape
    za, zb = (z[:, :, :-1], z[:, :, 1:]) if horizontal else (z[:, :-1, :], z[:, 1:, :])
    ia, ib = (ids[:, :, :-1], ids[:, :, 1:]) if horizontal else (ids[:, :-1, :], ids[:, 1:, :])
    candidate = _jumps(za, zb, ia, ib)
    if compact:
        bi, yi, xi = torch.nonzero(candidate).unbind(dim=1)  # how many: a wait for the device
        live = torch.ones_like(bi, dtype=torch.bool)
    else:
        bi, yi, xi = (
            index.flatten()
            for index in torch.meshgrid(*(torch.arange(n, device=z.device) for n in candidate.shape), indexing="ij")
        )
        live = candidate.flatten()
    a = yi * width + xi
    uv_a = torch.stack([xi + 0.5, yi + 0.5], dim=1).double()
    uv_b = uv_a.clone()
    uv_b[:, 0 if horizontal else 1] += 1.0
    rays_a, rays_b, R = _rays(K_inv, bi, uv_a), _rays(K_inv, bi, uv_b), _rows(pose[:, :3, :3], bi)
    pairs = _Candidates(
        bi,
        a,
        a + (1 if horizontal else width),
        torch.full_like(bi, horizontal, dtype=torch.bool),
        uv_a,
        uv_b,
        rays_a,
        rays_b,
        mat_vec(R, rays_a),
        mat_vec(R, rays_b),
        R,
        _rows(pose[:, :3, 3], bi),
        live,
    )
    flat_ids, flat_z = ids.reshape(batch, -1), z.reshape(batch, -1)
    # Neighbours on one continuous surface (a grazing floor's triangles) are no edge: the plane of
    # either one's triangle, extended to the other's ray, meets it at its depth. Dropping them here
    # spares the bisection most candidates; it would find no occlusion between them either.
    z_a, z_b = _pixels(flat_z, bi, pairs.a), _pixels(flat_z, bi, pairs.b)
    b_on_a = (_plane_depth(surfaces, _pixels(flat_ids, bi, pairs.a), pairs.world_b, pairs.c) - z_b).abs()
    a_on_b = (_plane_depth(surfaces, _pixels(flat_ids, bi, pairs.b), pairs.world_a, pairs.c) - z_a).abs()
    continuous = (b_on_a <= _CONTINUITY * z_b) & (a_on_b <= _CONTINUITY * z_a)
    return pairs.subset(~continuous, compact)


def _bisect(
    surfaces: Surfaces, pairs: _Candidates, flat_z: torch.Tensor, flat_ids: torch.Tensor, compact: bool
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Bisect each segment a -> b with real rays for where the foreground ends (uncompacted, only the
    live pairs' rays are cast).

    Each cast decides k steps (:data:`_STEPS_PER_CAST`): it casts every midpoint they could visit
    (the 2**k - 1 points of the bracket's grid), and the steps then pick theirs. The rays and the
    result are the same for every k; on a GPU, k = 3 takes a third of the casts, each tens of
    operations that its host launches one by one, for 7/3 as many rays.

    Returns the occluding triangle (N,), whether the depths on the two sides of the final bracket
    differ enough to be an occlusion (N,), and the crossing t in [0, 1] (N,).
    """
    bi = pairs.batch
    id_lo, id_hi = _pixels(flat_ids, bi, pairs.a), _pixels(flat_ids, bi, pairs.b)
    z_lo, z_hi = _pixels(flat_z, bi, pairs.a), _pixels(flat_z, bi, pairs.b)
    a_is_fg = z_lo <= z_hi
    fg_id = torch.where(a_is_fg, id_lo, id_hi)
    bg_id = torch.where(a_is_fg, id_hi, id_lo)
    lo, hi = torch.zeros_like(pairs.uv_a[:, 0]), torch.ones_like(pairs.uv_a[:, 0])
    # A ray through a point of the segment is affine in the point's position along it, and so are
    # its dot products with the two planes: everything but the cast is computed once.
    world_a, world_step = pairs.world_a, pairs.world_b - pairs.world_a
    (fg_normal, fg_offset), (bg_normal, bg_offset) = (
        _planes(surfaces, fg_id, pairs.c),
        _planes(surfaces, bg_id, pairs.c),
    )
    fg_a, fg_step = dot(fg_normal, world_a), dot(fg_normal, world_step)
    bg_a, bg_step = dot(bg_normal, world_a), dot(bg_normal, world_step)
    n = len(bi)
    per_cast = _STEPS_PER_CAST["cpu" if surfaces.device.type == "cpu" else "device"]
    for first in range(0, _BISECTION_STEPS, per_cast):
        steps = min(per_cast, _BISECTION_STEPS - first)
        points = 2**steps
        # the bracket's grid: lo + (hi - lo) k / points, k = 1 .. points - 1, exact in float64
        grid = torch.arange(1, points, dtype=lo.dtype, device=lo.device) / points
        mids = lo[:, None] + (hi - lo)[:, None] * grid  # (N, points - 1)
        live = None if compact else pairs.live[:, None].expand(-1, points - 1).reshape(-1)
        hits = surfaces.cast(
            pairs.c[:, None].expand(-1, points - 1, -1).reshape(-1, 3),
            (world_a[:, None] + mids[..., None] * world_step[:, None]).reshape(-1, 3),
            live,
        )
        z_fg = _plane_z(fg_id[:, None], fg_offset[:, None], fg_a[:, None] + mids * fg_step[:, None])
        z_bg = _plane_z(bg_id[:, None], bg_offset[:, None], bg_a[:, None] + mids * bg_step[:, None])
        # a hit is foreground up to a share of the way to the background's plane, and no further
        # than a bounded ratio beyond the foreground's own plane (a plane the ray misses: inf / inf)
        limit = z_fg * torch.clamp_max(1.0 + _FG_SHARE * (z_bg / z_fg - 1.0), _FG_MAX_RATIO)
        hit, ids = hits.hit.reshape(n, -1), hits.triangle_ids.reshape(n, -1)
        mid_z = torch.where(hit, hits.t.reshape(n, -1).double(), torch.inf)
        same_as_a = (hit & (mid_z < limit)) == a_is_fg[:, None]
        bracket = (lo, hi, id_lo, id_hi, z_lo, z_hi)
        lo, hi, id_lo, id_hi, z_lo, z_hi = _grid_steps(steps, mids, (same_as_a, ids, mid_z), bracket)
    occluder = torch.where(a_is_fg, id_lo, id_hi)
    near_z, far_z = torch.minimum(z_lo, z_hi), torch.maximum(z_lo, z_hi)
    occlusion = (occluder >= 0) & torch.isfinite(near_z) & ((far_z - near_z) > _CONTINUITY * near_z)
    return occluder, occlusion, 0.5 * (lo + hi)


def _grid_steps(steps: int, mids: torch.Tensor, cast: tuple, bracket: tuple) -> tuple:
    """``steps`` bisection steps on a bracket's grid of midpoints ``mids`` (N, 2**steps - 1): each
    step takes the midpoint of the grid points k_lo and k_hi that bracket the crossing, and moves
    one end of the ``bracket`` (lo, hi, id_lo, id_hi, z_lo, z_hi, each (N,)) there, by whether the
    ray through it meets what the segment's start does (``cast``: that, the triangle and the depth
    at every midpoint)."""
    lo, hi, id_lo, id_hi, z_lo, z_hi = bracket
    k_lo, k_hi = torch.zeros_like(id_lo), torch.full_like(id_lo, 2**steps)
    for _ in range(steps):
        k = ((k_lo + k_hi) // 2)[:, None]
        column = k - 1
        mid, step_same, step_ids, step_z = (values.gather(1, column)[:, 0] for values in (mids, *cast))
        lo, id_lo, z_lo = (
            torch.where(step_same, mid, lo),
            torch.where(step_same, step_ids, id_lo),
            torch.where(step_same, step_z, z_lo),
        )
        hi, id_hi, z_hi = (
            torch.where(step_same, hi, mid),
            torch.where(step_same, id_hi, step_ids),
            torch.where(step_same, z_hi, step_z),
        )
        k_lo, k_hi = torch.where(step_same, k[:, 0], k_lo), torch.where(step_same, k_hi, k[:, 0])
    return lo, hi, id_lo, id_hi, z_lo, z_hi


def _occluder_edge(
    surfaces: Surfaces, pairs: _Candidates, occluder: torch.Tensor, t_star: torch.Tensor, K: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Which of the occluder's three edges crosses the segment at ``t_star``.

    Returns its vertex indices (N, 2), how far (in segment units) its exact crossing lies from
    ``t_star`` (N,), and whether it is steep in the image (N,).
    """
    bi, R, c = pairs.batch, pairs.R, pairs.c
    faces = _rows(surfaces.faces, occluder.clamp_min(0))
    edges = torch.stack([faces, faces.roll(-1, dims=1)], dim=2)  # (N, 3, 2): (0, 1), (1, 2), (2, 0)
    vertices_cam = mat_vec(R.transpose(1, 2), _rows(surfaces.vertices, edges) - c[:, None, None])
    three = lambda tensor: tensor.repeat_interleave(3, dim=0)
    t_all, ok_all = edge_crossings(
        vertices_cam.reshape(-1, 2, 3), three(pairs.rays_a), three(pairs.rays_b), three(_rows(K, bi)),
        three(pairs.uv_a), three(pairs.uv_b),
    )  # fmt: skip
    n = len(bi)
    error = torch.where(ok_all, (t_all - three(t_star)).abs(), torch.inf).reshape(n, 3)
    best = error.argmin(dim=1)
    rows = torch.arange(n, device=best.device)
    chosen = edges[rows, best]
    v = _rows(surfaces.vertices, chosen)
    # image-plane direction of the edge (first order, at the crossing depth)
    direction_cam = mat_vec(R.transpose(1, 2), v[:, 1] - v[:, 0])
    return chosen, error[rows, best], direction_cam[:, 1].abs() >= direction_cam[:, 0].abs()


def find_edge_pairs(
    renderer: ExactRenderer,
    exact: RenderOutput,
    world_T_cam: torch.Tensor,
    K: torch.Tensor,
    compact: bool = True,
) -> EdgePairs:
    """Locate occlusion-edge pairs and their occluding triangle edges in exact renders (no gradient),
    on the renderer's device, where the pairs stay.

    Three steps: candidate neighbours across a depth jump in each direction, a bisection with real
    rays for the occluder and the crossing, and the occluder's edge that crosses there. With
    ``compact`` the candidates are compacted at each step (a GPU waits for their counts); otherwise
    every neighbour pair goes through, the others marked (:attr:`EdgePairs.keep`), and nothing waits.
    """
    surfaces, device = renderer.surfaces, renderer.device
    depth = exact.depth[:, 0].double().to(device)
    ids = exact.triangle_ids[:, 0].to(device)
    batch = depth.shape[0]
    pose = check_world_T_cam(world_T_cam).detach().double()
    K = batched_intrinsics(K, batch)
    K_inv = torch.linalg.inv(K).to(device, non_blocking=True)
    pose, K = pose.to(device, non_blocking=True), K.to(device, non_blocking=True)
    z = torch.where(depth > 0, depth, torch.inf)
    # both directions' candidates in one bisection: its casts are batched
    pairs = _Candidates.concatenate(
        [_candidate_pairs(surfaces, z, ids, pose, K_inv, horizontal, compact) for horizontal in (True, False)]
    )
    if not len(pairs.batch):
        empty = torch.zeros(0, dtype=torch.int64, device=device)
        none = torch.zeros(0, dtype=torch.bool, device=device)
        return EdgePairs(empty, empty, empty, none, empty.reshape(0, 2), empty.double())
    occluder, occlusion, t_star = _bisect(surfaces, pairs, z.reshape(batch, -1), ids.reshape(batch, -1), compact)
    chosen, error, steep = _occluder_edge(surfaces, pairs, occluder, t_star, K)
    keep = pairs.live & occlusion & (error < _MAX_CROSSING_ERROR) & (steep == pairs.horizontal)
    found = (pairs.batch, pairs.a, pairs.b, pairs.horizontal, chosen, t_star)
    if not compact:
        height, width = z.shape[1:]
        return EdgePairs(*found, keep=keep, blocks=(height * (width - 1), (height - 1) * width))
    rows = torch.nonzero(keep)[:, 0]
    return EdgePairs(*(values.index_select(0, rows) for values in found))


def _pair_centres(a: torch.Tensor, horizontal: torch.Tensor, width: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Pixel coordinates (N, 2) float64 of the centres of pairs' pixels a (N,) (flat indices in
    images ``width`` wide) and b (a's right neighbour where ``horizontal``, else the one below)."""
    ya, xa = a.div(width, rounding_mode="floor"), a.remainder(width)
    uv_a = torch.stack([xa + 0.5, ya + 0.5], dim=1).double()
    return uv_a, uv_a + torch.stack([horizontal, ~horizontal], dim=1).double()


@dataclass
class FoundEdges:
    """What :func:`track_edge_pairs` follows from one edge search: its pairs (compacted), each
    pair's edge (N, 2, 3) and the point on it (N, 3) where it crossed the segment between the
    pair's pixel centres (world frame), on the renderer's device. Computed once a search."""

    pairs: EdgePairs
    vertices: torch.Tensor
    points: torch.Tensor

    @classmethod
    def of(
        cls, renderer: ExactRenderer, pairs: EdgePairs, exact: RenderOutput, world_T_cam: torch.Tensor, K: torch.Tensor
    ) -> FoundEdges:
        """The pairs :func:`find_edge_pairs` found in ``exact``, rendered at ``world_T_cam`` (B, 4,
        4) with intrinsics ``K``."""
        pairs = pairs.compacted()
        device, bi = renderer.device, pairs.batch
        vertices = renderer.surfaces.vertices.double().index_select(0, pairs.edge.reshape(-1)).reshape(-1, 2, 3)
        pose = check_world_T_cam(world_T_cam).detach().double().to(device)
        R, c = _rows(pose[:, :3, :3], bi), _rows(pose[:, :3, 3], bi)
        K_inv = torch.linalg.inv(batched_intrinsics(K, len(pose)).to(device))
        uv_a, uv_b = _pair_centres(pairs.a, pairs.horizontal, exact.depth.shape[-1])
        vertices_cam = mat_vec(R.transpose(1, 2), vertices - c[:, None])
        share, _ = _edge_parameter(vertices_cam, _rays(K_inv, bi, uv_a), _rays(K_inv, bi, uv_b))
        return cls(pairs, vertices, vertices[:, 0] + share[:, None] * (vertices[:, 1] - vertices[:, 0]))


def track_edge_pairs(
    renderer: ExactRenderer, found: FoundEdges, exact: RenderOutput, world_T_cam: torch.Tensor, K: torch.Tensor
) -> EdgePairs:
    """The occlusion-edge pairs of a search (``found``), followed to nearby views ``world_T_cam``
    (B, 4, 4) with intrinsics ``K`` whose cast is ``exact`` (the searched render's size), without a
    ray: between a warp's refreshes, the outlines are the anchor's, moved.

    Each pair's crossing is a point on its occluder's edge; projected into the new view, the edge
    crosses the pixel row (a horizontal pair's) or column nearest to it between two pixel centres,
    which become the pair, kept where their depths in ``exact`` still jump and the edge is still
    as steep as the pair's direction says. Pairs two crossings land on are kept once. An edge
    that the anchor did not see (disoccluded, or come into the frame) has no pair until the search
    runs again.
    """
    device = renderer.device
    depth, ids = exact.depth[:, 0].double().to(device), exact.triangle_ids[:, 0].to(device)
    batch, height, width = depth.shape
    if not len(found.pairs.batch):
        return found.pairs
    bi, horizontal, vertices, point = found.pairs.batch, found.pairs.horizontal, found.vertices, found.points
    # the point and the edge's direction in the new view (projected, to first order)
    pose = check_world_T_cam(world_T_cam).detach().double().to(device)
    R_T = _rows(pose[:, :3, :3].transpose(1, 2), bi)
    KR = _rows(batched_intrinsics(K, batch).to(device), bi) @ R_T
    projected = mat_vec(KR, point - _rows(pose[:, :3, 3], bi))
    z = projected[:, 2].clamp_min(_MIN_PROJECTED_Z)
    uv = projected[:, :2] / z[:, None]
    towards = mat_vec(KR, vertices[:, 1] - vertices[:, 0])
    direction = (towards[:, :2] - uv * towards[:, 2:3]) / z[:, None]
    # the line of pixel centres (a row for a horizontal pair) nearest the point, where the edge crosses it
    along, across = torch.where(horizontal, uv[:, 1], uv[:, 0]), torch.where(horizontal, uv[:, 0], uv[:, 1])
    d_along = torch.where(horizontal, direction[:, 1], direction[:, 0])
    d_across = torch.where(horizontal, direction[:, 0], direction[:, 1])
    line = torch.floor(along)
    across = across + (line + 0.5 - along) * d_across / torch.where(d_along != 0, d_along, 1.0)
    first = torch.floor(across - 0.5)
    row = torch.where(horizontal, line, first).clamp(-1, height).long()
    column = torch.where(horizontal, first, line).clamp(-1, width).long()
    # steep as the search judges it (:func:`_occluder_edge`)
    edge_cam = mat_vec(R_T, vertices[:, 1] - vertices[:, 0])
    inside = (
        ((edge_cam[:, 1].abs() >= edge_cam[:, 0].abs()) == horizontal) & (d_along != 0)
        & (projected[:, 2] > _MIN_PROJECTED_Z) & (row >= 0) & (column >= 0)
        & (row < height - (~horizontal).long()) & (column < width - horizontal.long())
    )  # fmt: skip
    a = torch.where(inside, row * width + column, 0)
    b = a + torch.where(horizontal, 1, width)
    z_map, flat_ids = torch.where(depth > 0, depth, torch.inf).reshape(batch, -1), ids.reshape(batch, -1)
    jumps = _jumps(*(_pixels(z_map, bi, p) for p in (a, b)), *(_pixels(flat_ids, bi, p) for p in (a, b)))
    # one pair per pixel pair and direction: the first crossing that lands there
    rows = torch.nonzero(inside & jumps)[:, 0]
    key = (bi * 2 + horizontal) * (height * width) + a
    unique, group = torch.unique(key.index_select(0, rows), return_inverse=True)
    firsts = torch.full((len(unique),), len(rows), dtype=torch.int64, device=device)
    rows = rows.index_select(0, firsts.scatter_reduce(0, group, torch.arange(len(rows), device=device), "amin"))
    t = across - (first + 0.5)
    return EdgePairs(*(values.index_select(0, rows) for values in (bi, a, b, horizontal, found.pairs.edge, t)))


def _pair_poses(world_T_cam: torch.Tensor, pairs: EdgePairs) -> tuple[torch.Tensor, torch.Tensor]:
    """Each pair's view's rotation (N, 3, 3) and centre (N, 3), float64, differentiable.

    Pairs laid out view by view (every pair kept) take their view's pose by broadcasting on a GPU,
    so that the backward pass sums each view's pairs, a reduction; gathered, it would scatter N
    pairs into B poses, and a GPU serialises the many additions into one pose (twice the step, with
    155k pairs). The CPU gathers: its scatter is ordered, and gives a compacted search's sums.
    """
    if pairs.blocks is None or world_T_cam.device.type == "cpu":
        return world_T_cam[pairs.batch, :3, :3].double(), world_T_cam[pairs.batch, :3, 3].double()
    rows = torch.cat([world_T_cam.double()[:, None].expand(-1, n, 4, 4).reshape(-1, 4, 4) for n in pairs.blocks])
    return rows[:, :3, :3], rows[:, :3, 3]


def silhouette_term(
    renderer: ExactRenderer, pairs: EdgePairs, world_T_cam: torch.Tensor, K: torch.Tensor, values: torch.Tensor
) -> torch.Tensor:
    """Zero-valued (B, C, H, W) tensor whose gradient is the edge-motion derivative of ``values``.

    Args:
        pairs: from :func:`find_edge_pairs` on the exact render at ``world_T_cam``.
        world_T_cam: (B, 4, 4) current poses, differentiable.
        K: intrinsics (3, 3) or (B, 3, 3).
        values: (B, C, H, W) exact per-pixel values (detached) whose jumps the edges carry; the
            term is built on their device (the pose algebra runs on ``world_T_cam``'s).
    """
    check_shape(world_T_cam, "B 4 4", "world_T_cam", check_shape(values, "B C H W", "values"))
    batch, channels, height, width = values.shape
    device = values.device
    term = torch.zeros(batch * height * width, channels, dtype=torch.float64, device=device)
    if len(pairs.batch) == 0:
        return term.view(batch, height, width, channels).permute(0, 3, 1, 2).to(values.dtype) + (
            0 * world_T_cam.sum()
        ).to(device)
    pose_device = world_T_cam.device
    pairs = pairs.to(pose_device)
    K = batched_intrinsics(K, batch).to(pose_device, non_blocking=True)
    bi = pairs.batch
    R, c = _pair_poses(world_T_cam, pairs)
    vertices = renderer.surfaces.vertices.to(pose_device)[pairs.edge]  # (N, 2, 3) world
    vertices_cam = (vertices - c[:, None]) @ R  # R^T (v - c), row-vector form
    uv_a, uv_b = _pair_centres(pairs.a, pairs.horizontal, width)
    K_inv = torch.linalg.inv_ex(K)[0][bi]  # per view; inv_ex: no wait to check for singular matrices
    ones = torch.ones(len(bi), 1, dtype=torch.float64, device=pose_device)
    rays_a = (K_inv @ torch.cat([uv_a, ones], 1)[..., None])[..., 0]
    rays_b = (K_inv @ torch.cat([uv_b, ones], 1)[..., None])[..., 0]
    t, genuine = edge_crossings(vertices_cam, rays_a, rays_b, K[bi], uv_a, uv_b)
    far_b = pairs.t > 0.5
    # the pixel beyond the crossing's half is partly covered by its neighbour's surface
    coefficient = torch.where(far_b, t - 0.5, 0.5 - t) * genuine
    if pairs.keep is not None:  # the pairs that are no edges add nothing, and no gradient
        coefficient = torch.where(pairs.keep, coefficient, 0.0)
    coefficient = coefficient.to(device)
    # per pair where the pose is (its algebra), per pixel on the values' device
    flat = values.detach().double().permute(0, 2, 3, 1).reshape(batch, -1, channels)
    bi, far_b = bi.to(device), far_b.to(device)
    va, vb = flat[bi, pairs.a.to(device)], flat[bi, pairs.b.to(device)]
    blend = coefficient[:, None] * torch.where(far_b[:, None], va - vb, vb - va)
    target = bi * height * width + torch.where(pairs.t > 0.5, pairs.b, pairs.a).to(device)
    term = term.index_add(0, target, straight_through(blend))
    return term.view(batch, height, width, channels).permute(0, 3, 1, 2).to(values.dtype)
