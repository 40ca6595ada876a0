"""RGB-D views of procedural box rooms from random valid cameras (kadv-tiny's only training data)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from kadv.geometry import axis_angle_to_matrix, intrinsics_from_fov, look_at
from kadv.penalties import view_validity
from kadv.render import ExactRenderer, Shading
from kadv.scenes import box_room

__all__ = ["ViewBatch", "random_valid_poses", "render_procedural_views"]


@dataclass
class ViewBatch:
    """N rendered views: rgb (N, 3, H, W), depth (N, 1, H, W), mask (N, 1, H, W)."""

    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor


def random_valid_poses(renderer: ExactRenderer, count: int, rng: np.random.Generator, fov_x_deg: float,
                       min_clearance: float = 0.3) -> torch.Tensor:
    """``count`` poses (count, 4, 4) inside the scene bounds that :func:`view_validity` accepts.

    Centres are uniform in the bounds shrunk by ``min_clearance``; headings uniform, pitch in
    [-35, 15] degrees, roll within +-5 degrees.
    """
    lo, hi = renderer.scene.bounds + np.array([[min_clearance] * 3, [-min_clearance] * 3])
    accepted: list[torch.Tensor] = []
    K = intrinsics_from_fov(fov_x_deg, 24, 32)
    for _ in range(100):
        candidates = 4 * (count - len(accepted))
        centres = rng.uniform(lo, hi, size=(candidates, 3))
        yaw = rng.uniform(0, 2 * math.pi, candidates)
        pitch = np.radians(rng.uniform(-35, 15, candidates))
        forward = np.stack([np.cos(pitch) * np.cos(yaw), np.sin(pitch), np.cos(pitch) * np.sin(yaw)], axis=1)
        poses = look_at(torch.from_numpy(centres), torch.from_numpy(centres + forward)).double()
        roll = torch.from_numpy(np.radians(rng.uniform(-5, 5, candidates)))
        poses[:, :3, :3] = poses[:, :3, :3] @ axis_angle_to_matrix(torch.stack([0 * roll, 0 * roll, roll], dim=1))
        result = view_validity(renderer, poses, K, 24, 32)
        keep = result.valid & (result.distance >= min_clearance)
        accepted += list(poses[keep])
        if len(accepted) >= count:
            return torch.stack(accepted[:count])
    raise RuntimeError(f"found only {len(accepted)} of {count} valid views in {renderer.scene.name}")


def render_procedural_views(count: int, seed: int, height: int, width: int, views_per_room: int = 8,
                            progress: bool = True) -> ViewBatch:
    """Render ``count`` views from rooms ``box_room(seed * 100003 + i)`` with random shading.

    Deterministic for a seed; distinct seeds give disjoint rooms (held-out evaluation uses another seed).
    """
    rng = np.random.default_rng(seed)
    rgb, depth, mask = [], [], []
    rooms = math.ceil(count / views_per_room)
    for index in tqdm(range(rooms), desc="rendering rooms", disable=not progress):
        scene = box_room(seed=seed * 100003 + index, num_boxes=int(rng.integers(2, 8)))
        lo, hi = scene.bounds
        light = rng.uniform(lo + 0.3, hi - 0.3)
        shading = Shading(ambient=float(rng.uniform(0.3, 0.6)), diffuse=float(rng.uniform(0.3, 0.7)), lights=(tuple(light),))
        renderer = ExactRenderer(scene, shading)
        fov = float(rng.uniform(55, 85))
        n = min(views_per_room, count - index * views_per_room)
        poses = random_valid_poses(renderer, n, rng, fov)
        out = renderer.render(poses, intrinsics_from_fov(fov, height, width), height, width, supersample=2)
        rgb.append(out.rgb)
        depth.append(out.depth)
        mask.append(out.mask)
    return ViewBatch(torch.cat(rgb), torch.cat(depth), torch.cat(mask))
