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
from kadv.scenes import Scene, box_room, procedural_room
from kadv.scenes.procedural import CORRIDOR_SHARE, HALL_SHARE, ROOM_FEATURES, check_shares

__all__ = [
    "HELD_OUT_SEED",
    "MAX_SQUEEZED_ASPECT",
    "TRAINING_BAKE",
    "RoomMix",
    "ViewBatch",
    "render_procedural_views",
    "training_poses",
]

MAX_SQUEEZED_ASPECT = 2.0
"""The widest frame (width / height) a squeezed training view shows."""
TRAINING_BAKE = BakeConfig(texel=0.25, max_points=100_000, rays=256, light_samples=16)
"""The bake of a training room with baked lighting: a coarser lattice than the renderer's default
(a room costs seconds, not tens of seconds, and a training view is small), with more gather rays,
so that its indirect light is as smooth as a full bake's (with 32 rays on a 0.1 m lattice, as
before, walls lit by bounced light were mottled; the shipped stages up to kadv-tiny 7 and
kadv-tiny-dpt 6 trained on that)."""
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


@dataclass(frozen=True)
class RoomMix:
    """What the generated training rooms and their views are made of; every share lies in [0, 1].

    Attributes:
        furnished_share: rooms that are furnished rooms (``procedural_room``), spread evenly; the
            rest are box rooms lit from a random point.
        corridor_share, hall_share: furnished rooms that are corridors and halls (both 0: the rooms
            of the generator before it drew them).
        stairs_share, sun_share, glazing_share, trim_share, round_share: furnished rooms with a
            flight of stairs, with a sun through a window, windows that are glazed walls, with
            mouldings, and with round things (``procedural_room``'s shares).
        attack_view_share: views drawn as the attack draws its init views (eye height, a level
            gaze); the rest anywhere in the room.
        squeeze_share: rooms seen through a wider frame (aspect drawn up to ``MAX_SQUEEZED_ASPECT``)
            squeezed into the views' size, as a model that resizes every image sees wide photographs.
        baked_share: rooms, spread evenly, lit by their baked global illumination
            (``render.lighting=baked``, baked with ``bake``) instead of random direct shading.
        bake: the bake of those rooms (``TRAINING_BAKE``).
    With a share at 0, nothing it would draw is drawn, so the rooms and views are those drawn before
    it existed.
    """

    furnished_share: float = 0.0
    corridor_share: float = CORRIDOR_SHARE
    hall_share: float = HALL_SHARE
    stairs_share: float = 0.0
    sun_share: float = 0.0
    glazing_share: float = 0.0
    trim_share: float = 0.0
    round_share: float = 0.0
    attack_view_share: float = 0.0
    squeeze_share: float = 0.0
    baked_share: float = 0.0
    bake: BakeConfig = TRAINING_BAKE

    def check(self, prefix: str = "") -> None:
        """Raise ValueError, naming ``prefix`` + the key, unless each share lies in [0, 1] and the
        corridor and hall shares sum to at most 1."""
        check_shares(self.corridor_share, self.hall_share, prefix, **self.room_features())
        for name in ("furnished_share", "attack_view_share", "squeeze_share", "baked_share"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{prefix}{name} must be in [0, 1], got {getattr(self, name)}")

    def room_features(self) -> dict[str, float]:
        """The furnished rooms' feature shares, as ``procedural_room`` takes them."""
        return {name: getattr(self, name) for name in ROOM_FEATURES}


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


def _room(room_seed: int, index: int, mix: RoomMix, rng: np.random.Generator, bake) -> tuple[Scene, Shading]:
    """Room ``index`` of a batch and its random shading, as ``mix`` says (its draws from ``rng``)."""
    # room i is furnished when the running share first reaches the next whole room
    if math.floor((index + 1) * mix.furnished_share) > math.floor(index * mix.furnished_share):
        scene = procedural_room(
            seed=room_seed, corridor_share=mix.corridor_share, hall_share=mix.hall_share, **mix.room_features()
        )
        lights = None  # the room's own: its lamps and windows
    else:
        scene = box_room(seed=room_seed, num_boxes=int(rng.integers(2, 8)))
        lo, hi = scene.bounds
        lights = (tuple(rng.uniform(lo + 0.3, hi - 0.3)),)
    shading = Shading(ambient=float(rng.uniform(0.3, 0.6)), diffuse=float(rng.uniform(0.3, 0.7)), lights=lights)
    # spread evenly without drawing, so the other rooms' views are those drawn before the share existed
    if math.floor((index + 1) * mix.baked_share) > math.floor(index * mix.baked_share):
        shading = replace(shading, lighting="baked", bake=bake)
    return scene, shading


def render_procedural_views(
    count: int,
    seed: int,
    height: int,
    width: int,
    mix: RoomMix = RoomMix(),
    views_per_room: int = 8,
    progress: bool = True,
) -> ViewBatch:
    """Render ``count`` views, ``views_per_room`` per generated room, as ``mix`` says.

    Room ``i`` is ``procedural_room(seed * 100003 + i)`` (furnished, lit at its lamps and windows)
    for ``mix.furnished_share`` of the rooms, else ``box_room(seed * 100003 + i)`` lit from a random
    point, each under random direct shading or, for ``mix.baked_share`` of them, its baked light
    (into a scratch cache). Deterministic for a seed; distinct seeds give disjoint rooms (held-out
    evaluation uses another seed).

    Raises:
        ValueError: a share of ``mix`` outside [0, 1] (see :meth:`RoomMix.check`).
    """
    mix.check()
    # the rooms' bakes are made for this batch, into a scratch cache that goes with it
    with contextlib.ExitStack() as stack:
        folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="kadv-bakes-")) if mix.baked_share > 0 else None
        bake = replace(mix.bake, cache=folder)
        rng = np.random.default_rng(seed)
        rgb, depth, mask, world_T_cam, intrinsics = [], [], [], [], []
        rooms = math.ceil(count / views_per_room)
        for index in tqdm(range(rooms), desc="rendering rooms", disable=not progress):
            renderer = ExactRenderer(*_room(seed * 100003 + index, index, mix, rng, bake), progress=False)
            fov = float(rng.uniform(55, 85))
            n = min(views_per_room, count - index * views_per_room)
            poses = training_poses(renderer, n, rng, fov, mix.attack_view_share, height, width)
            K = intrinsics_from_fov(fov, height, width)
            # nothing is drawn when the share is 0, so those views are the views drawn before it existed
            if mix.squeeze_share > 0 and rng.random() < mix.squeeze_share:
                wide = round(height * rng.uniform(width / height, MAX_SQUEEZED_ASPECT))
                K = intrinsics_from_fov(fov, height, wide)
                K[0] *= width / wide  # the wide frame's columns squeezed into width
            out = renderer.render(poses, K, height, width, supersample=2).to("cpu")
            rgb.append(out.rgb)
            depth.append(out.depth)
            mask.append(out.mask)
            world_T_cam.append(poses)
            intrinsics.append(K.expand(len(poses), 3, 3))
        return ViewBatch(*(torch.cat(parts) for parts in (rgb, depth, mask, world_T_cam, intrinsics)))
