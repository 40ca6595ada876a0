"""render.lighting=scanned: a scan's captured colour shown as it is (vertex colours interpolated in
linear light, or the texel), with no lights; rays that meet nothing show the background."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import kadv
from kadv.render import ExactRenderer, Shading
from kadv.render.layers import render_anchor
from kadv.scenes.textures import linear_to_srgb, srgb_to_linear

# a 4 x 4 m wall 2 m in front of the origin, red on its +x side and blue on its -x side
WALL = np.array([[-2, -2, 2], [2, -2, 2], [2, 2, 2], [-2, 2, 2]], np.float32)
WALL_BYTES = np.array([[0, 0, 255], [255, 0, 0], [255, 0, 0], [0, 0, 255]], np.uint8)


def _wall(tmp_path: Path, width: float = 2.0) -> kadv.Scene:
    lines = ["ply", "format ascii 1.0", "element vertex 4", *(f"property float {a}" for a in "xyz")]
    lines += [f"property uchar {c}" for c in ("red", "green", "blue")]
    lines += ["element face 1", "property list uchar int vertex_indices", "end_header"]
    lines += [f"{x * width / 2} {y} {z} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(WALL, WALL_BYTES)]
    (tmp_path / "wall.ply").write_text("\n".join([*lines, "4 0 1 2 3"]) + "\n")
    return kadv.load_scene(tmp_path / "wall.ply")


def _looking_at_the_wall(renderer: ExactRenderer, size: int = 9, fov: float = 60.0, supersample: int = 1):
    pose = kadv.look_at(eye=[0.0, 0.0, 0.0], target=[0.0, 0.0, 1.0])
    return renderer.render(pose, kadv.intrinsics_from_fov(fov, size, size), size, size, supersample=supersample)


def test_vertex_colours_are_interpolated_in_linear_light_and_shown_as_captured(tmp_path: Path) -> None:
    out = _looking_at_the_wall(ExactRenderer(_wall(tmp_path), Shading(lighting="scanned")))
    assert out.mask.all()
    # image x runs towards world -x here: the wall's x at a pixel column, and the colour there
    K = kadv.intrinsics_from_fov(60.0, 9, 9)
    columns = torch.arange(9) + 0.5
    world_x = -(columns - K[0, 2]) / K[0, 0] * 2.0  # z = 2 m
    share_red = (world_x + 2.0) / 4.0  # linear in x from the blue side (-x) to the red (+x)
    red, blue = srgb_to_linear(np.ones(1))[0], 0.0
    expected = linear_to_srgb(np.stack([share_red * red, 0 * share_red, (1 - share_red) * red + blue], axis=1))
    np.testing.assert_allclose(out.rgb[0, :, 4].T.numpy(), expected, atol=2e-3)  # one row, every column
    # no light: every row of the wall the same, whatever its distance and angle to anything
    torch.testing.assert_close(out.rgb[0, :, 0], out.rgb[0, :, 8])


def test_a_ray_that_meets_nothing_shows_the_background_and_measures_no_depth(tmp_path: Path) -> None:
    scene = _wall(tmp_path, width=0.5)  # a narrow strip: most rays pass it
    grey = (0.2, 0.4, 0.6)
    out = _looking_at_the_wall(ExactRenderer(scene, Shading(lighting="scanned", background=grey)), size=16)
    missed = ~out.mask[0, 0]
    assert 0.3 < missed.float().mean() < 0.95
    torch.testing.assert_close(out.rgb[0][:, missed].T, torch.tensor(grey).expand(int(missed.sum()), 3))
    assert (out.depth[0, 0][missed] == 0).all() and (out.depth[0, 0][~missed] > 0).all()


def test_textured_surfaces_show_their_texels_as_stored(tmp_path: Path) -> None:
    room = kadv.box_room(seed=0)  # textures, no vertex colours
    renderer = ExactRenderer(room, Shading(lighting="scanned"))
    camera = room.cameras[0]
    K = kadv.intrinsics_from_fov(camera.fov_x_deg, 24, 32)
    out = renderer.render(camera.world_T_cam[None], K, 24, 32)
    ids = out.triangle_ids.flatten()
    origins, directions = kadv.geometry.camera.pixel_rays(camera.world_T_cam[None], K, 24, 32)
    hits = renderer.cast(origins.reshape(-1, 3), directions.reshape(-1, 3))
    assert torch.equal(hits.triangle_ids, ids)
    shaded = renderer.shader.shade(hits, origins.reshape(-1, 3), directions.reshape(-1, 3), 1e-6, geometry=False)
    footprint = torch.zeros(len(ids), dtype=torch.float64)  # finest texels, as the tiny pixel angle asks
    albedo = renderer.surfaces.albedo(ids.clamp_min(0), hits.barycentrics, footprint)
    torch.testing.assert_close(shaded["rgb"], albedo, atol=0.02, rtol=0)  # texel as stored, no light


def test_anchor_layers_carry_the_captured_colour_of_the_exact_render(tmp_path: Path) -> None:
    renderer = ExactRenderer(_wall(tmp_path), Shading(lighting="scanned"))
    pose = kadv.look_at(eye=[0.1, 0.2, 0.0], target=[0.0, 0.0, 1.0])
    K = kadv.intrinsics_from_fov(60.0, 12, 16)
    anchor = render_anchor(renderer, pose[None], K, 12, 16, supersample=1)
    exact = renderer.render(pose[None], K, 12, 16)
    torch.testing.assert_close(anchor.rgb[:, 0], exact.rgb)


def test_scanned_lighting_without_a_captured_colour_is_refused_naming_the_key() -> None:
    plain = kadv.Scene(
        vertices=WALL,
        faces=[[0, 1, 2], [0, 2, 3]],
        uvs=np.zeros((2, 3, 2), np.float32),
        normals=np.tile(np.array([0, 0, -1], np.float32), (2, 3, 1)),
        material_ids=[0, 0],
        materials=[kadv.scenes.Material("plain")],
        name="plain",
    )
    with pytest.raises(
        ValueError, match=r"render.lighting=scanned: scene 'plain' has no vertex colours and no textures"
    ):
        ExactRenderer(plain, Shading(lighting="scanned"))
