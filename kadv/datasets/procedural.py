"""RGB-D views of procedural box rooms from random valid cameras (kadv-tiny's only training data)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from kadv.geometry import intrinsics_from_fov
from kadv.penalties import random_valid_poses
from kadv.render import ExactRenderer, Shading
from kadv.scenes import box_room

__all__ = ["ViewBatch", "render_procedural_views"]


@dataclass
class ViewBatch:
    """N rendered views: rgb (N, 3, H, W), depth (N, 1, H, W), mask (N, 1, H, W)."""

    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor


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
