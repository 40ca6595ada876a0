"""RGB-D views of generated rooms from random valid cameras (the embedded models' only training data)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from kadv.geometry import intrinsics_from_fov
from kadv.penalties import random_valid_poses
from kadv.render import ExactRenderer, Shading
from kadv.scenes import box_room, procedural_room
from kadv.scenes.procedural import CORRIDOR_SHARE, HALL_SHARE

__all__ = ["HELD_OUT_SEED", "ViewBatch", "render_procedural_views"]

HELD_OUT_SEED = 7
"""The seed of the generated rooms the embedded models are measured on (``benchmarks/tiny_accuracy.py``);
no training run may draw it."""


@dataclass
class ViewBatch:
    """N rendered views: rgb (N, 3, H, W), depth (N, 1, H, W), mask (N, 1, H, W)."""

    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor


def render_procedural_views(
    count: int,
    seed: int,
    height: int,
    width: int,
    views_per_room: int = 8,
    furnished_share: float = 0.0,
    progress: bool = True,
    corridor_share: float = CORRIDOR_SHARE,
    hall_share: float = HALL_SHARE,
) -> ViewBatch:
    """Render ``count`` views, ``views_per_room`` per generated room, under random shading.

    Room ``i`` is ``procedural_room(seed * 100003 + i)`` (furnished, lit at its lamps and windows;
    ``corridor_share`` and ``hall_share`` pass to it) for a ``furnished_share`` of the rooms, spread
    evenly, else ``box_room(seed * 100003 + i)`` lit from a random point. Deterministic for a seed;
    distinct seeds give disjoint rooms (held-out evaluation uses another seed).
    """
    if not 0.0 <= furnished_share <= 1.0:
        raise ValueError(f"furnished_share must be in [0, 1], got {furnished_share}")
    rng = np.random.default_rng(seed)
    rgb, depth, mask = [], [], []
    rooms = math.ceil(count / views_per_room)
    for index in tqdm(range(rooms), desc="rendering rooms", disable=not progress):
        room_seed = seed * 100003 + index
        # room i is furnished when the running share first reaches the next whole room
        if math.floor((index + 1) * furnished_share) > math.floor(index * furnished_share):
            scene = procedural_room(seed=room_seed, corridor_share=corridor_share, hall_share=hall_share)
            lights = None  # the room's own: its lamps and windows
        else:
            scene = box_room(seed=room_seed, num_boxes=int(rng.integers(2, 8)))
            lo, hi = scene.bounds
            lights = (tuple(rng.uniform(lo + 0.3, hi - 0.3)),)
        shading = Shading(ambient=float(rng.uniform(0.3, 0.6)), diffuse=float(rng.uniform(0.3, 0.7)), lights=lights)
        renderer = ExactRenderer(scene, shading)
        fov = float(rng.uniform(55, 85))
        n = min(views_per_room, count - index * views_per_room)
        poses = random_valid_poses(renderer, n, rng, fov)
        out = renderer.render(poses, intrinsics_from_fov(fov, height, width), height, width, supersample=2)
        rgb.append(out.rgb)
        depth.append(out.depth)
        mask.append(out.mask)
    return ViewBatch(torch.cat(rgb), torch.cat(depth), torch.cat(mask))
