"""Anchor RGB-D layers: exact renders at a pose, kept for differentiable reprojection.

Layer 0 is the visible surface, at s x s rays per pixel; layer k the k-th front-facing surface
behind it along each pixel's centre ray (depth peeling by casting on from beyond each hit; an
occluder's own back faces are stepped through), so pixels hidden at the anchor can still be found
when the camera moves. An
optional guard band widens the field of view (same centre, same focal length) so that samples near
the current view's border have real content.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import torch

from kadv.geometry.camera import batched_intrinsics, camera_rays, world_rays
from kadv.geometry.pose import check_world_T_cam
from kadv.render.exact import ExactRenderer, RayHits, concatenated, pixel_angle, views_apart
from kadv.render.surface import Surfaces

__all__ = [
    "RING",
    "AnchorLayers",
    "BoxedLayers",
    "camera_face_normals",
    "guard_band_intrinsics",
    "render_anchor",
    "ring_view",
]


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

    @cached_property
    def boxed(self) -> BoxedLayers:
        """The layers box-filtered to the current views' pixels (computed once per anchor)."""
        return BoxedLayers.of(self)

    def to(self, device: torch.device | str) -> AnchorLayers:
        """The same layers with every map on ``device``; the pose and intrinsics stay where they are."""
        maps = {name: getattr(self, name).to(device) for name in ("rgb", "points", "normals", "triangle_ids", "mask")}
        reflecting = None if self.reflecting is None else self.reflecting.to(device)
        return AnchorLayers(self.world_T_cam, self.K, self.supersample, self.guard_band, **maps, reflecting=reflecting)


@dataclass
class BoxedLayers:
    """An anchor's layers box-filtered to the current views' pixel size: each pixel of the anchor's
    fine image holds the mean over an s x s block of them around its corner, as an exact render's
    pixel does over its own rays. At the anchor's pose a view's pixel centre falls on one of these;
    elsewhere the filter can be read anywhere, half a fine pixel apart.

    Attributes:
        K: (B, 3, 3) intrinsics of the boxed images (the fine anchor's, shifted by the block's centre).
        maps: (B, L, 7, Hs - s + 1, Ws - s + 1) float32: colour (3), anchor-frame point (3) and 1
            where every sample of the block hit a surface (else 0).
    """

    K: torch.Tensor
    maps: torch.Tensor

    @cached_property
    def diagonal_means(self) -> torch.Tensor:
        """(B, L, 6, h + 1, w + 1) the colour and point of each 2 x 2 block of the maps (zero beyond
        them): pixel (i, j) is the mean of maps (i - 1 .. i, j - 1 .. j), centred on the maps' pixel
        corner (i, j). Its bilinear lookup at q is the mean of the maps' four lookups at q +- (1/2,
        1/2), to rounding (both are piecewise linear with the same knots): one lookup for four."""
        padded = torch.nn.functional.pad(self.maps[:, :, 0:6], (1, 1, 1, 1))
        return _box_reduce(padded, 2, torch.empty_like(padded[..., 1:, 1:]), torch.add).mul_(0.25)

    @classmethod
    def of(cls, anchor: AnchorLayers) -> BoxedLayers:
        """Box-filter ``anchor``'s colour and points (mean) and its mask (least) over s x s
        blocks at every fine pixel (stride 1), written straight into the maps: sums of shifted
        slices, a fifth of the time of avg_pool2d and max_pool2d over a concatenated copy on the CPU."""
        s = anchor.supersample
        batch, layers, _, height, width = anchor.rgb.shape
        size = (height - s + 1, width - s + 1)
        maps = anchor.rgb.new_empty(batch, layers, 7, *size)
        for source, channels in ((anchor.rgb, slice(0, 3)), (anchor.points, slice(3, 6))):
            _box_reduce(source, s, maps[:, :, channels], torch.add).div_(s * s)
        full = _box_reduce(anchor.mask, s, torch.empty_like(anchor.mask[..., : size[0], : size[1]]), torch.logical_and)
        maps[:, :, 6:7] = full
        K = anchor.K.clone()
        K[..., :2, 2] -= (s - 1) / 2  # block (i, j) is centred on fine pixel (i, j)'s centre + (s - 1) / 2
        return cls(K, maps)


def _box_reduce(image: torch.Tensor, s: int, out: torch.Tensor, combine) -> torch.Tensor:
    """``out`` (..., h - s + 1, w - s + 1) := ``combine`` (torch.add, torch.logical_and) of the s x s
    fine pixels from each one of ``image`` (..., h, w), as a sum of shifted slices."""
    height, width = out.shape[-2:]
    shifted = [image[..., i : i + height, j : j + width] for i in range(s) for j in range(s)]
    out.copy_(shifted[0])
    for other in shifted[1:]:
        combine(out, other, out=out)
    return out


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


# A layer's search casts again from just beyond the last hit: this far, relative to its distance
# (and at least a micrometre), so that a coplanar duplicate (z-fighting) is stepped over too.
_BEYOND = 1e-5
# casts behind a layer, at most, to find the next front-facing surface: an occluder's back face,
# then what it hides, with room for a few thin shells in between
_PEEL_CASTS = 4


def _peel(renderer: ExactRenderer, origins: torch.Tensor, directions: torch.Tensor, first: RayHits, layers: int):
    """Along each ray (N, 3) with first hits ``first``: the next ``layers - 1`` front-facing
    surfaces behind it, nearest first, each found by casting on from just beyond the hit before.
    A closed occluder's own back faces are stepped through: what a moved camera finds behind an
    object is what the object hides, not its far side."""
    out, behind = [], first
    for _ in range(1, layers):
        found = RayHits(torch.full_like(first.t, torch.inf), torch.full_like(first.triangle_ids, -1),
                        torch.zeros_like(first.barycentrics))  # fmt: skip
        live, start = behind.hit, torch.where(behind.hit, behind.t, 0.0).double()
        for _ in range(_PEEL_CASTS):
            if not bool(live.any()):
                break
            start = start + torch.clamp(_BEYOND * start, min=1e-6)
            hits = renderer.surfaces.cast(origins + start[:, None] * directions, directions, live)
            t = start + torch.where(hits.hit, hits.t.double(), 0.0)
            front = hits.hit & (renderer.surfaces.facing(hits.triangle_ids.clamp_min(0), directions) < 0)
            take = live & front
            found.t = torch.where(take, t.float(), found.t)
            found.triangle_ids = torch.where(take, hits.triangle_ids, found.triangle_ids)
            found.barycentrics = torch.where(take[:, None], hits.barycentrics, found.barycentrics)
            live, start = live & hits.hit & ~front, t
        out.append(found)
        behind = found
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
    if views_apart(K):  # each view's pixels filtered at its own footprint
        return concatenated([
            render_anchor(renderer, pose[b : b + 1], K[b], height, width, layers, guard_band, supersample)
            for b in range(batch)
        ])  # fmt: skip
    K_anchor = guard_band_intrinsics(K, guard_band, supersample)
    h, w = supersample * (height + 2 * guard_band), supersample * (width + 2 * guard_band)
    rays_cam = camera_rays(K_anchor, h, w, device=renderer.device)
    origins, directions = (rays.reshape(-1, 3) for rays in world_rays(pose, rays_cam))
    rays_cam = rays_cam.reshape(batch, -1, 3)
    # cast and shaded in parts of render.max_rays
    first, shaded = renderer.cast_and_shade(origins, directions, pixel_angle(K_anchor), colour=True, geometry=False)
    layered = [_layer_maps(renderer, first, shaded, rays_cam, pose)]
    if layers > 1:
        # the layers behind, one ray per pixel (its centre): they fill what a move uncovers, where
        # a quarter of the rays serve as well as all of them
        K_centres = guard_band_intrinsics(K, guard_band, 1)
        centre_cam = camera_rays(K_centres, h // supersample, w // supersample, device=renderer.device)
        o, d = (rays.reshape(-1, 3) for rays in world_rays(pose, centre_cam))
        centre_angle = pixel_angle(K_centres)
        for hits in _peel(renderer, o, d, renderer.cast(o, d), layers):
            behind = renderer.shader.shade(hits, o, d, centre_angle, geometry=False)
            maps = _layer_maps(renderer, hits, behind, centre_cam.reshape(batch, -1, 3), pose)
            layered.append({key: _upsampled(value, h // supersample, supersample) for key, value in maps.items()})

    def stack(key: str) -> torch.Tensor:
        tensor = torch.stack([maps[key] for maps in layered], dim=1)  # (B, L, N, C)
        return tensor.reshape(batch, len(layered), h, w, -1).permute(0, 1, 4, 2, 3).contiguous()

    reflecting = shaded.get("reflecting")
    if reflecting is not None:
        reflecting = reflecting.reshape(batch, h, w, 6).permute(0, 3, 1, 2).contiguous()
    keys = ("rgb", "points", "normals", "ids", "mask")
    return AnchorLayers(pose, K_anchor, supersample, guard_band, *(stack(key) for key in keys), reflecting)


def _layer_maps(
    renderer: ExactRenderer, hits: RayHits, shaded: dict[str, torch.Tensor], rays_cam: torch.Tensor, pose: torch.Tensor
) -> dict[str, torch.Tensor]:
    """One layer's maps (B, N, C) from its hits and shading on camera-frame rays (B, N, 3)."""
    batch = len(pose)
    ids = hits.triangle_ids.reshape(batch, -1)
    depth = torch.where(hits.hit, hits.t.double(), 0.0).reshape(batch, -1, 1)
    return {
        "rgb": shaded["rgb"].reshape(batch, -1, 3),
        "points": (depth * rays_cam).float(),  # 0 where invalid
        "normals": camera_face_normals(renderer.surfaces, ids, pose).float(),
        "ids": ids[..., None],
        "mask": ids[..., None] >= 0,
    }


def _upsampled(values: torch.Tensor, height: int, s: int) -> torch.Tensor:
    """(B, height * width, C) per-pixel values repeated over each pixel's s x s block: (B, s^2 height width, C)."""
    batch, _, channels = values.shape
    image = values.reshape(batch, height, -1, channels)
    return image.repeat_interleave(s, dim=1).repeat_interleave(s, dim=2).reshape(batch, -1, channels)
