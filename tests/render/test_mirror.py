"""A perfect mirror in the exact render: it shows what its specular bounce meets under every lighting,
and its depth is its own surface's."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.geometry import intrinsics_from_fov, look_at
from kadv.render import BakeConfig, ExactRenderer, Shading
from kadv.scenes import Material, assemble_scene
from kadv.scenes.parts import facing, quad_part, room_shell_parts

SIZE = (4.0, 3.0, 4.0)
MIRROR_X = 0.05
EYE = (3.0, 1.5, 2.0)


def _solid(colour) -> Material:
    """A plain surface with a texture of its colour (scanned lighting shows textures as captured)."""
    return Material("solid", base_color=np.ones(3), texture=np.broadcast_to(np.float32(colour), (4, 4, 3)).copy())


def _mirror_room(mirror: bool = True, both_walls: bool = False):
    """A 4 x 3 x 4 m grey room whose wall at x = 4 is red, with a mirror hung on the wall at x = 0
    (and, with ``both_walls``, another facing it at x = 4)."""
    grey, red = _solid([0.6, 0.6, 0.6]), _solid([0.8, 0.0, 0.0])
    glass = Material("mirror", base_color=np.full(3, 0.9), mirror=mirror)
    parts = room_shell_parts(SIZE, [0, 0, 0, 0, 0, 1], 1.0)
    for x, toward in [(MIRROR_X, 1.0)] + ([(SIZE[0] - MIRROR_X, -1.0)] if both_walls else []):
        corners = [[x, 0.5, 3.5], [x, 0.5, 0.5], [x, 2.5, 0.5], [x, 2.5, 3.5]]
        parts.append(quad_part(facing(corners, [toward, 0.0, 0.0]), 2, "mirror"))
    return assemble_scene(parts, [grey, red, glass], name="mirror_room")


def _render(scene, lighting: str, tmp_path):
    bake = BakeConfig(texel=0.25, rays=16, light_samples=1, cache=str(tmp_path))
    renderer = ExactRenderer(scene, Shading(lighting=lighting, bake=bake), progress=False)
    pose = look_at(torch.tensor(EYE, dtype=torch.float64), torch.tensor([0.0, 1.5, 2.0], dtype=torch.float64))
    return renderer.render(pose, intrinsics_from_fov(60.0, 48, 64), 48, 64)


@pytest.mark.parametrize("lighting", ["direct", "baked", "scanned"])
def test_the_mirror_shows_the_red_wall_behind_the_camera(lighting: str, tmp_path) -> None:
    out = _render(_mirror_room(), lighting, tmp_path)
    centre = out.rgb[0, :, 18:30, 24:40]  # the mirror's middle, whose bounce meets the red wall
    assert (centre[0] > 0.05).all(), "red is seen in the mirror"
    assert centre[1:].abs().max() < 1e-3, "and nothing but red: no grey of the mirror's own"
    plain = _render(_mirror_room(mirror=False), lighting, tmp_path).rgb[0, :, 18:30, 24:40]
    assert (plain[1] > 0.05).all()  # the same surface, not a mirror: its own grey
    # its depth is the mirror's plane: the eye looks along -x at x = 0.05
    torch.testing.assert_close(
        out.depth[0, 0, 18:30, 24:40], torch.full((12, 16), EYE[0] - MIRROR_X), atol=1e-4, rtol=0
    )


def test_facing_mirrors_end_after_a_few_bounces(tmp_path) -> None:
    out = _render(_mirror_room(both_walls=True), "direct", tmp_path)
    centre = out.rgb[0, :, 22:26, 30:34]
    # between two grey mirrors the bounces end on a mirror's own grey, tinted by 0.9 a bounce:
    # grey, and darker than the mirror's own shading seen directly
    assert torch.isfinite(centre).all() and (centre[0] - centre[1]).abs().max() < 1e-6
    plain = _render(_mirror_room(mirror=False, both_walls=True), "direct", tmp_path).rgb[0, :, 22:26, 30:34]
    assert (centre < plain).all()
