"""RGB-D views of generated rooms from random valid cameras (the embedded models' only training data)."""

from __future__ import annotations

import contextlib
import math
import tempfile
from dataclasses import dataclass, replace

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack.init_views import InitViewConfig, sample_valid_views
from kadv.geometry import intrinsics_from_fov
from kadv.penalties import PenaltyConfig, random_valid_poses
from kadv.render import BakeConfig, ExactRenderer, Shading
from kadv.scenes import box_room, procedural_room
from kadv.scenes.procedural import CORRIDOR_SHARE, HALL_SHARE

__all__ = [
    "HELD_OUT_SEED",
    "MAX_SQUEEZED_ASPECT",
    "TRAINING_BAKE",
    "ViewBatch",
    "check_view_shares",
    "render_procedural_views",
    "training_poses",
]

MAX_SQUEEZED_ASPECT = 2.0
"""The widest frame (width / height) a squeezed training view shows."""
TRAINING_BAKE = BakeConfig(texel=0.1, max_points=300_000, rays=32, light_samples=16)
"""The bake of a training room with baked lighting: coarser than the renderer's default (a room costs
seconds, not tens of seconds), since a training view is small."""
HELD_OUT_SEED = 7
"""The seed of the generated rooms the embedded models are measured on (``benchmarks/tiny_accuracy.py``);
no training run may draw it."""


@dataclass
class ViewBatch:
    """N rendered views: rgb (N, 3, H, W), depth (N, 1, H, W), mask (N, 1, H, W), and where known
    the cameras: world_T_cam (N, 4, 4) and intrinsics (N, 3, 3), float64."""

    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor
    world_T_cam: torch.Tensor | None = None
    intrinsics: torch.Tensor | None = None


def check_view_shares(
    furnished_share: float, attack_view_share: float, squeeze_share: float, baked_share: float, prefix: str = ""
) -> None:
    """Raise ValueError, naming ``prefix`` + the key, unless each share lies in [0, 1]."""
    shares = {
        "furnished_share": furnished_share,
        "attack_view_share": attack_view_share,
        "squeeze_share": squeeze_share,
        "baked_share": baked_share,
    }
    for name, share in shares.items():
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"{prefix}{name} must be in [0, 1], got {share}")


def training_poses(
    renderer: ExactRenderer,
    count: int,
    rng: np.random.Generator,
    fov_x_deg: float,
    attack_view_share: float,
    height: int,
    width: int,
) -> torch.Tensor:
    """``count`` valid poses (count, 4, 4) for training views: about ``attack_view_share`` of them
    drawn as the attack draws init views at ``height`` x ``width``, first, the rest anywhere in the
    scene's camera region."""
    # nothing extra is drawn when the share is 0, so those views are the views drawn before it existed
    wanted = int(rng.binomial(count, attack_view_share)) if attack_view_share > 0 else 0
    eye_level = torch.zeros(0, 4, 4, dtype=torch.float64)
    if wanted:
        config = InitViewConfig(fov_x_deg=fov_x_deg)
        eye_level = sample_valid_views(
            renderer, wanted, int(rng.integers(2**31)), config, PenaltyConfig(), height, width
        )
    rest = count - len(eye_level)  # a room with no free space at eye height gets views from anywhere
    return torch.cat([eye_level, random_valid_poses(renderer, rest, rng, fov_x_deg)]) if rest else eye_level


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
    attack_view_share: float = 0.0,
    squeeze_share: float = 0.0,
    baked_share: float = 0.0,
) -> ViewBatch:
    """Render ``count`` views, ``views_per_room`` per generated room, under random shading.

    Room ``i`` is ``procedural_room(seed * 100003 + i)`` (furnished, lit at its lamps and windows;
    ``corridor_share`` and ``hall_share`` pass to it) for a ``furnished_share`` of the rooms, spread
    evenly, else ``box_room(seed * 100003 + i)`` lit from a random point. An
    ``attack_view_share`` of the views are drawn as the attack draws its init views (eye height
    above the floor, a level gaze: :func:`~kadv.attack.sample_valid_views`), the rest anywhere in
    the room (:func:`~kadv.penalties.random_valid_poses`). A ``squeeze_share`` of the rooms are
    seen through a wider frame (aspect drawn up to ``MAX_SQUEEZED_ASPECT``) squeezed into ``height``
    x ``width``, as a model that resizes every image to its input size sees wide photographs. A
    ``baked_share`` of the rooms, spread evenly, are lit by their baked global illumination
    (``render.lighting=baked``, baked with ``TRAINING_BAKE`` into a scratch cache) instead of random
    direct shading.
    Deterministic for a seed; distinct seeds give disjoint rooms (held-out evaluation uses another
    seed).
    """
    check_view_shares(furnished_share, attack_view_share, squeeze_share, baked_share)
    # the rooms' bakes are made for this batch, into a scratch cache that goes with it
    with contextlib.ExitStack() as stack:
        folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="kadv-bakes-")) if baked_share > 0 else None
        bake = replace(TRAINING_BAKE, cache=folder)
        rng = np.random.default_rng(seed)
        rgb, depth, mask, world_T_cam, intrinsics = [], [], [], [], []
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
            # spread evenly without drawing, so the other rooms' views are those drawn before the share existed
            if math.floor((index + 1) * baked_share) > math.floor(index * baked_share):
                shading = replace(shading, lighting="baked", bake=bake)
            renderer = ExactRenderer(scene, shading, progress=False)
            fov = float(rng.uniform(55, 85))
            n = min(views_per_room, count - index * views_per_room)
            poses = training_poses(renderer, n, rng, fov, attack_view_share, height, width)
            K = intrinsics_from_fov(fov, height, width)
            # nothing is drawn when the share is 0, so those views are the views drawn before it existed
            if squeeze_share > 0 and rng.random() < squeeze_share:
                wide = round(height * rng.uniform(width / height, MAX_SQUEEZED_ASPECT))
                K = intrinsics_from_fov(fov, height, wide)
                K[0] *= width / wide  # the wide frame's columns squeezed into width
            out = renderer.render(poses, K, height, width, supersample=2)
            rgb.append(out.rgb)
            depth.append(out.depth)
            mask.append(out.mask)
            world_T_cam.append(poses)
            intrinsics.append(K.expand(len(poses), 3, 3))
        return ViewBatch(*(torch.cat(parts) for parts in (rgb, depth, mask, world_T_cam, intrinsics)))
