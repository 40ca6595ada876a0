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
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from kadv.geometry.camera import pixel_rays
from kadv.geometry.pose import check_world_T_cam
from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface
from kadv.render.raycast import ExactRenderer, RenderOutput

__all__ = ["ViewValidity", "fibonacci_sphere", "probe_directions_hits", "view_validity"]

VALID, INSIDE, OUTSIDE, TOO_CLOSE = "valid", "inside an object", "outside the scene", "too close"


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
        verdicts: one of "valid", "inside an object", "outside the scene", "too close" per camera.
        reasons: a sentence per camera saying why.
    """

    miss_fraction: torch.Tensor
    back_face_fraction: torch.Tensor
    near_fraction: torch.Tensor
    probe_miss_fraction: torch.Tensor
    probe_back_fraction: torch.Tensor
    distance: torch.Tensor
    verdicts: list[str]
    reasons: list[str]

    @property
    def valid(self) -> torch.Tensor:
        return torch.tensor([v == VALID for v in self.verdicts])


def fibonacci_sphere(count: int) -> np.ndarray:
    """(count, 3) nearly uniform unit directions (golden-angle spiral), deterministic."""
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    radius = np.sqrt(1.0 - z * z)
    angle = np.pi * (1.0 + 5**0.5) * index
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)


def probe_directions_hits(renderer: ExactRenderer, centres: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(miss, back) booleans (B, N) for rays from each centre (B, 3) along each direction (N, 3)."""
    origins = np.broadcast_to(centres[:, None, :], (len(centres), len(directions), 3))
    rays = np.broadcast_to(directions[None], origins.shape)
    hits = renderer.cast(origins, rays)
    shape = (len(centres), len(directions))
    return ~hits.hit.reshape(shape), renderer.back_facing(hits, rays).reshape(shape)


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
    render: RenderOutput | None = None,
) -> ViewValidity:
    """Classify B camera views.

    Args:
        renderer: the scene's exact renderer (its ray caster is reused).
        world_T_cam: (B, 4, 4) or (4, 4) poses.
        K: (3, 3) or (B, 3, 3) intrinsics.
        height, width: the view's image size.
        near: near plane in metres (z-depth); pixels closer than it make the view "too close".
        min_distance: the centre may not be nearer than this to any surface.
        probe_rays: directions of the spherical probe.
        outside_threshold: probe miss fraction above which the centre is outside the scene.
        inside_threshold: probe back-face fraction above which the centre is inside an object.
        render: the views' exact render at these poses, K and size, when the caller has one: its
            pixel-centre hits are used instead of casting them again.
    """
    pose = check_world_T_cam(world_T_cam)
    centres = pose[:, :3, 3].detach().double().numpy()
    batch = len(centres)
    if render is None:
        origins, directions = pixel_rays(pose, K, height, width)
        hits = renderer.cast(origins, directions)
        hit = hits.hit.reshape(batch, -1)
        view_back = renderer.back_facing(hits, directions).reshape(batch, -1)
        near_hit = hit & (hits.t.reshape(batch, -1) < near)
    else:
        if tuple(render.depth.shape) != (batch, 1, height, width):
            raise ValueError(f"render: expected depth ({batch}, 1, {height}, {width}), got {tuple(render.depth.shape)}")
        hit = (render.triangle_ids >= 0).reshape(batch, -1).numpy()
        view_back = render.back_face.reshape(batch, -1).numpy()
        near_hit = hit & (render.depth.reshape(batch, -1).double().numpy() < near)
    probe_miss, probe_back = probe_directions_hits(renderer, centres, fibonacci_sphere(probe_rays))
    distance = distance_to_surface(renderer, torch.from_numpy(centres)).numpy()
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
            reasons.append(f"centre {distance[b]:.3f} m from a surface, {near_hit[b].mean():.1%} of pixels nearer "
                           f"than {near} m (limits {min_distance} m, 0 pixels)")
        else:
            verdicts.append(VALID)
            reasons.append(f"enclosed ({miss_frac:.0%} escape, {back_frac:.0%} back faces), {distance[b]:.2f} m clear")
    as_tensor = lambda a: torch.from_numpy(np.asarray(a, np.float64))  # noqa: E731
    return ViewValidity(
        miss_fraction=as_tensor((~hit).mean(axis=1)),
        back_face_fraction=as_tensor(view_back.mean(axis=1)),
        near_fraction=as_tensor(near_hit.mean(axis=1)),
        probe_miss_fraction=as_tensor(probe_miss.mean(axis=1)),
        probe_back_fraction=as_tensor(probe_back.mean(axis=1)),
        distance=as_tensor(distance),
        verdicts=verdicts,
        reasons=reasons,
    )
