"""kadv.datasets.room_views: RGB-D views of generated rooms."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.datasets import MAX_SQUEEZED_ASPECT, RoomMix, render_procedural_views, training_poses
from kadv.geometry import intrinsics_from_fov
from kadv.penalties import view_validity
from kadv.render import ExactRenderer
from kadv.scenes import box_room


def test_views_are_deterministic_per_seed_and_consistent() -> None:
    first = render_procedural_views(6, seed=3, height=12, width=16, views_per_room=3, progress=False)
    again = render_procedural_views(6, seed=3, height=12, width=16, views_per_room=3, progress=False)
    other = render_procedural_views(6, seed=4, height=12, width=16, views_per_room=3, progress=False)
    assert first.rgb.shape == (6, 3, 12, 16) and first.depth.shape == first.mask.shape == (6, 1, 12, 16)
    assert torch.equal(first.rgb, again.rgb) and torch.equal(first.depth, again.depth)
    assert not torch.equal(first.depth, other.depth)
    assert torch.equal(first.mask, first.depth > 0)
    assert float(first.mask.float().mean()) > 0.95  # views from inside closed rooms


def test_a_share_of_the_rooms_is_furnished() -> None:
    boxes = render_procedural_views(4, seed=3, height=12, width=16, views_per_room=2, progress=False)
    mixed = render_procedural_views(
        4, seed=3, height=12, width=16, views_per_room=2, mix=RoomMix(furnished_share=0.5), progress=False
    )
    # room 0 is a box room in both, room 1 is furnished in the mix
    assert torch.equal(boxes.rgb[:2], mixed.rgb[:2])
    assert not torch.equal(boxes.depth[2:], mixed.depth[2:])
    with pytest.raises(ValueError, match="furnished_share"):
        render_procedural_views(4, seed=3, height=12, width=16, mix=RoomMix(furnished_share=1.5), progress=False)


def test_an_attack_view_share_draws_views_at_eye_height_with_a_level_gaze() -> None:
    renderer = ExactRenderer(box_room(seed=3, num_boxes=0))  # floor at y = 0, nothing on it
    anywhere = training_poses(renderer, 16, np.random.default_rng(0), 70.0, 0.0, 12, 16)
    eye_level = training_poses(renderer, 16, np.random.default_rng(0), 70.0, 1.0, 12, 16)
    # the init views' defaults: 1.0-1.8 m above the floor, pitch -25 to 10 degrees
    height = eye_level[:, 1, 3]
    assert bool(((height > 1.0 - 1e-9) & (height < 1.8 + 1e-9)).all()), height
    pitch = torch.rad2deg(torch.asin(eye_level[:, 1, 2]))  # the optical axis' (y up) upward part
    assert bool(((pitch > -25.0 - 1e-6) & (pitch < 10.0 + 1e-6)).all()), pitch
    assert not bool(((anywhere[:, 1, 3] > 1.0) & (anywhere[:, 1, 3] < 1.8)).all()), anywhere[:, 1, 3]
    half = training_poses(renderer, 16, np.random.default_rng(0), 70.0, 0.5, 12, 16)
    K = intrinsics_from_fov(70.0, 12, 16)
    assert half.shape == (16, 4, 4) and bool(view_validity(renderer, half, K, 12, 16).valid.all())
    with pytest.raises(ValueError, match="attack_view_share"):
        render_procedural_views(4, seed=3, height=12, width=16, mix=RoomMix(attack_view_share=-0.1), progress=False)


def test_a_squeeze_share_renders_wider_frames_into_the_same_pixels() -> None:
    plain = render_procedural_views(8, seed=3, height=12, width=16, views_per_room=4, progress=False)
    squeezed = render_procedural_views(
        8, seed=3, height=12, width=16, views_per_room=4, mix=RoomMix(squeeze_share=1.0), progress=False
    )
    K = squeezed.intrinsics
    assert squeezed.rgb.shape == plain.rgb.shape
    assert torch.equal(plain.intrinsics[:, 0, 0], plain.intrinsics[:, 1, 1])  # square pixels
    aspect = (16 / 12) * K[:, 1, 1] / K[:, 0, 0]  # the frame's width / height before it was squeezed
    # drawn up to 2:1, then rounded to whole columns (a draw near 4:3 may round to the frame itself)
    assert bool(((aspect > 16 / 12 - 1e-9) & (aspect <= MAX_SQUEEZED_ASPECT + 1 / 12)).all()), aspect
    assert bool((aspect > 1.4).any()), aspect
    # the drawn horizontal field of view (55-85 degrees) over the 16 columns, a vertical one no wider
    fov_x = torch.rad2deg(2 * torch.atan(8 / K[:, 0, 0]))
    assert bool(((fov_x > 55 - 1e-9) & (fov_x < 85 + 1e-9)).all()) and bool((K[:, 1, 1] >= K[:, 0, 0]).all())
    with pytest.raises(ValueError, match="squeeze_share"):
        render_procedural_views(4, seed=3, height=12, width=16, mix=RoomMix(squeeze_share=1.5), progress=False)


def test_a_baked_share_lights_rooms_by_their_baked_global_illumination(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("KADV_CACHE", str(tmp_path))  # where a bake would go if it were kept
    direct = render_procedural_views(4, seed=3, height=12, width=16, views_per_room=2, progress=False)
    half = render_procedural_views(
        4, seed=3, height=12, width=16, views_per_room=2, mix=RoomMix(baked_share=0.5), progress=False
    )
    again = render_procedural_views(
        4, seed=3, height=12, width=16, views_per_room=2, mix=RoomMix(baked_share=0.5), progress=False
    )
    # room 0 keeps its direct shading, room 1 is baked: the same cameras and depth, other colours
    assert torch.equal(direct.rgb[:2], half.rgb[:2]) and torch.equal(direct.depth, half.depth)
    assert not torch.equal(direct.rgb[2:], half.rgb[2:]) and torch.equal(half.rgb, again.rgb)
    assert not any(tmp_path.rglob("*.npz"))  # the bakes went to a scratch cache, now gone
    with pytest.raises(ValueError, match="baked_share"):
        render_procedural_views(4, seed=3, height=12, width=16, mix=RoomMix(baked_share=2.0), progress=False)


def test_the_room_features_reach_the_furnished_rooms_only() -> None:
    features = RoomMix(stairs_share=1.0, sun_share=1.0, glazing_share=1.0)
    boxes = render_procedural_views(2, seed=3, height=12, width=16, views_per_room=2, progress=False)
    assert torch.equal(boxes.depth, render_procedural_views(2, 3, 12, 16, features, 2, progress=False).depth)
    furnished = RoomMix(furnished_share=1.0)
    plain = render_procedural_views(2, seed=3, height=12, width=16, mix=furnished, views_per_room=2, progress=False)
    featured = render_procedural_views(
        2, 3, 12, 16, RoomMix(**{**features.room_features(), "furnished_share": 1.0}), 2, progress=False
    )
    assert not torch.equal(plain.depth, featured.depth)
    with pytest.raises(ValueError, match="stairs_share"):
        render_procedural_views(2, seed=3, height=12, width=16, mix=RoomMix(stairs_share=-1.0), progress=False)
