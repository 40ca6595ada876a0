"""Is a camera view legitimate? Inside an object, outside the scene, too close, or valid.

Open3D's signed distance decides its sign by ray parity, which is meaningless for open rooms
(windows, missing ceilings); the verdict here comes from a spherical probe of rays around the
optical centre instead:

- *outside the scene*: more than ``outside_threshold`` (0.3) of the probe directions escape. A
  room's windows and doors rarely let a fifth of all directions out, while anywhere under open
  sky, even over an endless ground plane, about half of them escape;
- *inside an object*: most probe directions first hit the back of a triangle. Exporters write
  closed objects with outward normals and rooms with inward normals, so from free space one sees
  front faces. One- and two-sided materials are treated alike in this vote: the back of a
  two-sided panel (a painting, a leaf) is legitimately visible, but only over the minority of
  directions the panel covers, so it cannot swing the majority; a one-sided surface seen from
  behind counts the same way.
- *too close*: the centre is nearer than ``min_distance`` to a surface or some of the view's
  pixels are nearer than the near plane.
- *uninformative*: a view that is otherwise valid but where one plane (a wall seen close, the
  floor) covers more than ``max_plane_share`` of the pixels that hit a surface. A lone plane's
  ground truth, min-max normalised, is a ramp that a model's nearly flat guess misses by a wide
  margin while its delta1 stays near 1, so the view's L_depth says nothing about the model.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import torch

from kadv.checks import check_shape
from kadv.geometry.camera import pixel_rays
from kadv.geometry.pose import check_world_T_cam
from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface
from kadv.render.raycast import ExactRenderer, RenderOutput

__all__ = ["ViewValidity", "fibonacci_sphere", "plane_labels", "plane_shares", "probe_directions_hits", "view_validity"]

VALID, INSIDE, OUTSIDE, TOO_CLOSE = "valid", "inside an object", "outside the scene", "too close"
UNINFORMATIVE = "uninformative"
# Triangles lie in one plane when their unit normals agree to ~1 degree and their offsets to 2 cm:
# coarse enough for a wall split into many triangles, fine enough to part a table top from the floor.
_PLANE_NORMAL_STEP, _PLANE_OFFSET_STEP = 0.02, 0.02
_PLANE_LABELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass
class ViewValidity:
    """Per-camera validity statistics (B cameras).

    Attributes:
        miss_fraction: (B,) fraction of the view's pixels whose ray hits nothing.
        back_face_fraction: (B,) fraction of the view's pixels that see the back of a triangle.
        near_fraction: (B,) fraction of the view's pixels closer than the near plane.
        probe_miss_fraction: (B,) fraction of spherical probe directions that escape.
        probe_back_fraction: (B,) fraction of probe directions whose first hit is a back face.
        distance: (B,) distance from the optical centre to the nearest surface, metres.
        plane_share: (B,) share of the pixels that hit a surface which lie on the most common plane.
        verdicts: one of "valid", "inside an object", "outside the scene", "too close",
            "uninformative" per camera.
        reasons: a sentence per camera saying why.
    """

    miss_fraction: torch.Tensor
    back_face_fraction: torch.Tensor
    near_fraction: torch.Tensor
    probe_miss_fraction: torch.Tensor
    probe_back_fraction: torch.Tensor
    distance: torch.Tensor
    plane_share: torch.Tensor
    verdicts: list[str]
    reasons: list[str]

    @property
    def valid(self) -> torch.Tensor:
        return torch.tensor([v == VALID for v in self.verdicts])


def fibonacci_sphere(count: int) -> np.ndarray:
    """(count, 3) nearly uniform unit directions (golden-angle spiral), deterministic.

    Examples:
        >>> directions = fibonacci_sphere(100)
        >>> directions.shape, bool(np.allclose(np.linalg.norm(directions, axis=1), 1.0))
        ((100, 3), True)
        >>> bool(abs(directions.mean(axis=0)).max() < 0.02)  # spread evenly: their mean is near 0
        True
    """
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    radius = np.sqrt(1.0 - z * z)
    angle = np.pi * (1.0 + 5**0.5) * index
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)


def plane_labels(renderer: ExactRenderer) -> np.ndarray:
    """(F,) int64 label per triangle of the renderer's scene; coplanar triangles share a label
    (computed once per scene).

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> len(np.unique(plane_labels(room)))  # floor, ceiling and four walls
        6
    """
    if renderer not in _PLANE_LABELS:
        scene = renderer.scene
        corners = scene.vertices[scene.faces]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        # n and -n are one plane: make each normal's largest component positive
        sign = np.sign(np.take_along_axis(normal, np.abs(normal).argmax(axis=1)[:, None], axis=1))
        normal *= np.where(sign == 0, 1.0, sign)
        offset = np.einsum("fi,fi->f", normal, corners[:, 0])
        keys = np.concatenate(
            [np.round(normal / _PLANE_NORMAL_STEP), np.round(offset / _PLANE_OFFSET_STEP)[:, None]], axis=1
        )
        _PLANE_LABELS[renderer] = np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1)
    return _PLANE_LABELS[renderer]


def plane_shares(renderer: ExactRenderer, triangle_ids: np.ndarray) -> np.ndarray:
    """(B,) share of each view's hit pixels that lie on its most common plane (0 for a view that
    hits nothing), from per-pixel triangle ids (B, N) with -1 for a miss.

    Examples:
        >>> import kadv
        >>> from kadv.geometry import intrinsics_from_fov, look_at
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> facing_wall = look_at(torch.tensor([2.0, 1.5, 4.0]), torch.tensor([2.0, 1.5, 5.0]))  # 1 m from it
        >>> corner = look_at(torch.tensor([1.0, 2.0, 1.0]), torch.tensor([4.0, 0.0, 5.0]))
        >>> out = room.render(torch.stack([facing_wall, corner]), intrinsics_from_fov(60.0, 24, 32), 24, 32)
        >>> shares = plane_shares(room, out.triangle_ids[:, 0].numpy())
        >>> shares[0].item(), shares[1].item() < 0.9
        (1.0, True)
    """
    labels = plane_labels(renderer)
    shares = np.zeros(len(triangle_ids))
    for b, ids in enumerate(triangle_ids):
        hit = ids[ids >= 0]
        if len(hit):
            shares[b] = np.bincount(labels[hit]).max() / len(hit)
    return shares


def probe_directions_hits(
    renderer: ExactRenderer, centres: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(miss, back) booleans (B, N) for rays from each centre (B, 3) along each direction (N, 3).

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> centres = np.array([[2.0, 1.5, 2.5], [2.0, 1.5, -1.0]])  # inside; outside, behind the wall z = 0
        >>> miss, back = probe_directions_hits(room, centres, fibonacci_sphere(64))
        >>> miss.any(axis=1).tolist(), back.any(axis=1).tolist()  # from outside: escaping rays, back faces
        ([False, True], [False, True])
    """
    origins = np.broadcast_to(centres[:, None, :], (len(centres), len(directions), 3))
    rays = np.broadcast_to(directions[None], origins.shape)
    hits = renderer.cast(origins, rays)
    shape = (len(centres), len(directions))
    back = renderer.back_facing(hits, rays).cpu().numpy()
    return ~hits.hit.cpu().numpy().reshape(shape), back.reshape(shape)


def view_validity(
    renderer: ExactRenderer,
    world_T_cam: torch.Tensor,
    K: torch.Tensor,
    height: int,
    width: int,
    *,
    near: float = PenaltyConfig.near,
    min_distance: float = PenaltyConfig.min_distance,
    probe_rays: int = PenaltyConfig.probe_rays,
    outside_threshold: float = PenaltyConfig.outside_threshold,
    inside_threshold: float = PenaltyConfig.inside_threshold,
    max_plane_share: float | None = PenaltyConfig.max_plane_share,
    render: RenderOutput | None = None,
) -> ViewValidity:
    """Classify B camera views.

    Args:
        renderer: the scene's exact renderer (its ray caster is reused).
        world_T_cam: (B, 4, 4) or (4, 4) poses.
        K: (3, 3) or (B, 3, 3) intrinsics.
        height: the view's image height.
        width: the view's image width.
        near: near plane in metres (z-depth); pixels closer than it make the view "too close".
        min_distance: the centre may not be nearer than this to any surface.
        probe_rays: directions of the spherical probe.
        outside_threshold: probe miss fraction above which the centre is outside the scene.
        inside_threshold: probe back-face fraction above which the centre is inside an object.
        max_plane_share: a view whose most common plane covers more of its hit pixels than this is
            "uninformative" (None: never).
        render: the views' exact render at these poses, K and size, when the caller has one: its
            pixel-centre hits are used instead of casting them again.

    Examples:
        >>> import kadv
        >>> from kadv.geometry import intrinsics_from_fov, look_at
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> eyes = torch.tensor([[1.0, 1.5, 1.0], [1.0, 1.5, -1.0]])  # inside the room; behind its wall z = 0
        >>> poses = look_at(eyes, torch.tensor([[3.0, 1.0, 4.0], [3.0, 1.0, 4.0]]))
        >>> verdicts = view_validity(room, poses, intrinsics_from_fov(70.0, 24, 32), 24, 32)
        >>> verdicts.valid.tolist(), verdicts.verdicts
        ([True, False], ['valid', 'outside the scene'])
    """
    pose = check_world_T_cam(world_T_cam)
    centres = pose[:, :3, 3].detach().double().numpy()
    batch = len(centres)
    if render is None:
        origins, directions = pixel_rays(pose, K, height, width)
        hits = renderer.cast(origins, directions)
        view_back = renderer.back_facing(hits, directions).cpu().numpy().reshape(batch, -1)
        hits = hits.numpy()
        triangle_ids = hits.triangle_ids.reshape(batch, -1)
        hit = hits.hit.reshape(batch, -1)
        near_hit = hit & (hits.t.reshape(batch, -1) < near)
    else:
        check_shape(render.depth, f"B 1 {height} {width}", "render.depth", {"B": batch})
        triangle_ids = render.triangle_ids.reshape(batch, -1).cpu().numpy()
        hit = triangle_ids >= 0
        view_back = render.back_face.reshape(batch, -1).cpu().numpy()
        near_hit = hit & (render.depth.reshape(batch, -1).double().cpu().numpy() < near)
    probe_miss, probe_back = probe_directions_hits(renderer, centres, fibonacci_sphere(probe_rays))
    distance = distance_to_surface(renderer, torch.from_numpy(centres)).numpy()
    share = plane_shares(renderer, triangle_ids)
    verdicts, reasons = [], []
    for b in range(batch):
        miss_frac, back_frac = probe_miss[b].mean(), probe_back[b].mean()
        if miss_frac > outside_threshold:
            verdicts.append(OUTSIDE)
            reasons.append(f"{miss_frac:.0%} of probe rays escape the scene (> {outside_threshold:.0%})")
        elif back_frac > inside_threshold:
            verdicts.append(INSIDE)
            reasons.append(f"{back_frac:.0%} of probe rays first hit a back face (> {inside_threshold:.0%})")
        elif distance[b] < min_distance or near_hit[b].any():
            verdicts.append(TOO_CLOSE)
            reasons.append(
                f"centre {distance[b]:.3f} m from a surface, {near_hit[b].mean():.1%} of pixels nearer "
                f"than {near} m (limits {min_distance} m, 0 pixels)"
            )
        elif max_plane_share is not None and share[b] > max_plane_share:
            verdicts.append(UNINFORMATIVE)
            reasons.append(f"one plane covers {share[b]:.0%} of the surface pixels (> {max_plane_share:.0%})")
        else:
            verdicts.append(VALID)
            reasons.append(f"enclosed ({miss_frac:.0%} escape, {back_frac:.0%} back faces), {distance[b]:.2f} m clear")
    as_tensor = lambda a: torch.from_numpy(np.asarray(a, np.float64))
    return ViewValidity(
        miss_fraction=as_tensor((~hit).mean(axis=1)),
        back_face_fraction=as_tensor(view_back.mean(axis=1)),
        near_fraction=as_tensor(near_hit.mean(axis=1)),
        probe_miss_fraction=as_tensor(probe_miss.mean(axis=1)),
        probe_back_fraction=as_tensor(probe_back.mean(axis=1)),
        distance=as_tensor(distance),
        plane_share=as_tensor(share),
        verdicts=verdicts,
        reasons=reasons,
    )
