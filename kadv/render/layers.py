"""Anchor RGB-D layers: exact renders at a pose, kept for differentiable reprojection.

Layer 0 is the visible surface; layer k the k-th front-facing surface behind it along each ray
(depth peeling with Open3D's ``list_intersections``, sorted per ray; an occluder's own back faces
are skipped), so pixels hidden at the anchor can still be found when the camera moves. An
optional guard band widens the field of view (same centre, same focal length) so that samples near
the current view's border have real content.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from kadv.geometry.camera import batched_intrinsics, camera_rays, world_rays
from kadv.geometry.pose import check_world_T_cam
from kadv.render.raycast import ExactRenderer, RayHits, pixel_angle
from kadv.render.surface import Surfaces

__all__ = ["RING", "AnchorLayers", "camera_face_normals", "guard_band_intrinsics", "render_anchor", "ring_view"]


@dataclass
class AnchorLayers:
    """L layers of B anchor views at resolution (Hs, Ws) = supersample x (H + 2g, W + 2g).

    Attributes:
        world_T_cam: (B, 4, 4) anchor poses.
        K: (B, 3, 3) intrinsics of the hi-res anchor images.
        supersample: s, sub-pixels per current-view pixel along each axis.
        guard_band: g, extra current-view pixels on each side.
        rgb: (B, L, 3, Hs, Ws) float32 shaded colour, background where invalid.
        points: (B, L, 3, Hs, Ws) float32 camera-frame points (z = depth), 0 where invalid.
        normals: (B, L, 3, Hs, Ws) float32 camera-frame geometric (face) normals.
        triangle_ids: (B, L, 1, Hs, Ws) int64, -1 where invalid.
        mask: (B, L, 1, Hs, Ws) bool.
        reflecting: (B, 6, Hs, Ws) float32 the first layer's reflection terms when coats and metals
            reflect (:meth:`~kadv.render.shading.Shader.shade`'s "reflecting"), else None: what an
            exact render at the anchor's pose needs beside the colours it takes from the anchor.
    """

    world_T_cam: torch.Tensor
    K: torch.Tensor
    supersample: int
    guard_band: int
    rgb: torch.Tensor
    points: torch.Tensor
    normals: torch.Tensor
    triangle_ids: torch.Tensor
    mask: torch.Tensor
    reflecting: torch.Tensor | None = None

    @property
    def num_layers(self) -> int:
        return self.rgb.shape[1]

    def to(self, device: torch.device | str) -> AnchorLayers:
        """The same layers with every map on ``device``; the pose and intrinsics stay where they are."""
        maps = {name: getattr(self, name).to(device) for name in ("rgb", "points", "normals", "triangle_ids", "mask")}
        reflecting = None if self.reflecting is None else self.reflecting.to(device)
        return AnchorLayers(self.world_T_cam, self.K, self.supersample, self.guard_band, **maps, reflecting=reflecting)


def guard_band_intrinsics(K: torch.Tensor, guard_band: int, supersample: int) -> torch.Tensor:
    """Intrinsics (B, 3, 3) of the anchor image: principal point shifted by the band, all scaled by s."""
    K = torch.as_tensor(K, dtype=torch.float64).clone()
    K[..., 0, 2] += guard_band
    K[..., 1, 2] += guard_band
    K[..., :2, :] *= supersample
    return K


RING = 1  # pixels of the ring around a frame


def ring_view(K: torch.Tensor, height: int, width: int) -> tuple[torch.Tensor, int, int]:
    """Intrinsics (B, 3, 3) and size of the frame plus a one-pixel ring around it.

    Occlusion edges just outside the frame enter it when the camera moves; they are found on the
    ring. The frame's own render is the ring render's interior (the same rays), ``cropped(RING)``.
    """
    return guard_band_intrinsics(K, RING, 1), height + 2 * RING, width + 2 * RING


def camera_face_normals(surfaces: Surfaces, triangle_ids: torch.Tensor, world_T_cam: torch.Tensor) -> torch.Tensor:
    """Camera-frame geometric normals (B, ..., 3) float64 of triangles ``triangle_ids`` (B, ...) of
    ``surfaces``, on the surfaces' device (where their face normals already are); 0 where an id is -1."""
    triangle_ids = triangle_ids.to(surfaces.device)
    face = surfaces.face_normals.index_select(0, triangle_ids.clamp_min(0).flatten())
    rotation = world_T_cam[:, :3, :3].detach().double().to(surfaces.device)
    normals = (face.reshape(len(rotation), -1, 3) @ rotation).reshape(*triangle_ids.shape, 3)  # rows: (R^T n)^T
    return torch.where((triangle_ids >= 0)[..., None], normals, 0.0)


def _peel(renderer: ExactRenderer, origins: torch.Tensor, directions: torch.Tensor, layers: int) -> list[RayHits]:
    """Along each ray (N, 3): the visible surface (its first opaque hit), then the next ``layers - 1``
    front-facing surfaces behind it, nearest first. A closed occluder's own back faces are left
    out: what a moved camera finds behind an object is what the object hides, not its far side."""
    n = len(origins)
    ray_ids, t, ids, bary = renderer.intersections(origins, directions)
    # Coplanar duplicates (z-fighting) would fill several layers with one surface.
    t64 = t.double()
    keep = torch.ones_like(ray_ids, dtype=torch.bool)
    keep[1:] = ~((ray_ids[1:] == ray_ids[:-1]) & ((t64[1:] - t64[:-1]).abs() <= 1e-5 * t64[1:].clamp_min(1e-6)))
    ray_ids, t, ids, bary = ray_ids[keep], t[keep], ids[keep], bary[keep]
    first = torch.searchsorted(ray_ids, torch.arange(n, device=ray_ids.device))
    order = torch.arange(len(ray_ids), device=ray_ids.device)
    visible = order == first[ray_ids]
    rays = torch.as_tensor(directions, device=renderer.surfaces.device).double()[ray_ids.to(renderer.surfaces.device)]
    front = (renderer.surfaces.facing(ids.long().to(rays.device), rays) < 0).to(ray_ids.device)
    # the visible hit is layer 0; the front-facing hits behind it are layers 1, 2, ... in order
    behind = ~visible & front
    counted = torch.cumsum(behind.long(), dim=0)
    before = torch.cat([counted.new_zeros(1), counted])[first]  # each ray's: those of the rays before it
    rank = torch.where(visible, 0, torch.where(behind, counted - before[ray_ids], -1))
    out = []
    for layer in range(layers):
        selected = rank == layer
        hits = RayHits(
            torch.full((n,), torch.inf, device=t.device),
            torch.full((n,), -1, dtype=torch.int64, device=t.device),
            torch.zeros(n, 2, device=t.device),
        )
        hits.t[ray_ids[selected]] = t[selected]
        hits.triangle_ids[ray_ids[selected]] = ids[selected]
        hits.barycentrics[ray_ids[selected]] = bary[selected]
        out.append(hits)
    return out


def render_anchor(
    renderer: ExactRenderer,
    world_T_cam: torch.Tensor,
    K: torch.Tensor,
    height: int,
    width: int,
    layers: int = 1,
    guard_band: int = 0,
    supersample: int = 1,
) -> AnchorLayers:
    """Render anchor layers for views of size (height, width) at ``world_T_cam`` (B, 4, 4).

    Args:
        renderer: the scene's exact renderer.
        world_T_cam: anchor poses; detached (anchors carry no gradient).
        K: intrinsics (3, 3) or (B, 3, 3) of the current views.
        layers: number of depth layers (1 = visible surface only).
        guard_band: extra pixels of field of view on each side.
        supersample: anchor resolution per current-view pixel along each axis.
    """
    pose = check_world_T_cam(world_T_cam).detach().double()
    batch = pose.shape[0]
    K = batched_intrinsics(K, batch)
    K_anchor = guard_band_intrinsics(K, guard_band, supersample)
    h, w = supersample * (height + 2 * guard_band), supersample * (width + 2 * guard_band)
    rays_cam = camera_rays(K_anchor, h, w, device=renderer.device)
    origins, directions = (rays.reshape(-1, 3) for rays in world_rays(pose, rays_cam))
    rays_cam = rays_cam.reshape(batch, -1, 3)
    angle = pixel_angle(K_anchor)
    if layers == 1:  # cast and shaded in parts of render.max_rays
        layered = [renderer.cast_and_shade(origins, directions, angle, colour=True, geometry=False)]
    else:
        peeled = _peel(renderer, origins, directions, layers)
        layered = [(hits, renderer.shader.shade(hits, origins, directions, angle, geometry=False)) for hits in peeled]
    maps = {key: [] for key in ("rgb", "points", "normals", "ids", "mask")}
    for hits, shaded in layered:
        ids = hits.triangle_ids.reshape(batch, -1)
        depth = torch.where(hits.hit, hits.t.double(), 0.0).reshape(batch, -1, 1)
        maps["rgb"].append(shaded["rgb"].reshape(batch, -1, 3))
        maps["points"].append((depth * rays_cam).float())  # 0 where invalid
        maps["normals"].append(camera_face_normals(renderer.surfaces, ids, pose).float())
        maps["ids"].append(ids[..., None])
        maps["mask"].append(ids[..., None] >= 0)

    def stack(key: str) -> torch.Tensor:
        tensor = torch.stack(maps[key], dim=1)  # (B, L, N, C)
        return tensor.reshape(batch, len(layered), h, w, -1).permute(0, 1, 4, 2, 3).contiguous()

    reflecting = layered[0][1].get("reflecting")
    if reflecting is not None:
        reflecting = reflecting.reshape(batch, h, w, 6).permute(0, 3, 1, 2).contiguous()
    return AnchorLayers(pose, K_anchor, supersample, guard_band, *(stack(key) for key in maps), reflecting)
