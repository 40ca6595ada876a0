from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.geometry import intrinsics_from_fov, look_at, pixel_rays
from kadv.render import ExactRenderer, Shading
from kadv.render.exact import pixel_angle
from kadv.scenes import Material, assemble_scene, box_room
from kadv.scenes.parts import quad_part

FLAT = Shading(ambient=1.0, diffuse=0.0, background=(0.25, 0.5, 0.75))
RED, BLUE = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def _checker_texture(cells: int = 4, texels: int = 8) -> np.ndarray:
    rows, cols = np.indices((cells * texels, cells * texels)) // texels
    return np.where(((rows + cols) % 2 == 0)[:, :, None], RED, BLUE).astype(np.float32)


def _quad_scene(opacity: np.ndarray | None = None, wall_behind: bool = False):
    materials = [
        Material("checker", base_color=np.ones(3), texture=_checker_texture(), opacity=opacity),
        Material("wall", base_color=np.array([0.0, 1.0, 0.0])),
    ]
    parts = [quad_part(np.array([[-1, -1, 2], [1, -1, 2], [1, 1, 2], [-1, 1, 2]], float), 0, "quad")]
    if wall_behind:
        parts.append(quad_part(np.array([[-5, -5, 4], [5, -5, 4], [5, 5, 4], [-5, 5, 4]], float), 1, "wall"))
    return assemble_scene(parts, materials, name="quad")


def _analytic_room_depth(size, world_T_cam, K, height, width) -> np.ndarray:
    """z-depth of the nearest of the six room planes along every pixel ray."""
    origins, dirs = pixel_rays(world_T_cam, K, height, width)
    o, d = origins.reshape(-1, 3).numpy(), dirs.reshape(-1, 3).numpy()
    best = np.full(len(d), np.inf)
    for axis in range(3):
        for plane in (0.0, size[axis]):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (plane - o[:, axis]) / d[:, axis]
            best = np.where((t > 0) & (t < best), t, best)
    return best.reshape(height, width)


@pytest.mark.parametrize("omega", [(0.0, 0.0, 0.0), (0.2, -0.4, 0.3)])
def test_wall_depth_equals_analytic_plane_distance(omega) -> None:
    size = (5.0, 3.0, 4.0)
    scene = box_room(seed=1, size=size, num_boxes=0)
    pose = look_at(torch.tensor([1.0, 1.4, 1.5]), torch.tensor([4.0, 1.0, 3.0])).double()
    pose[:3, :3] = pose[:3, :3] @ torch.linalg.matrix_exp(
        torch.tensor(
            [[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]], dtype=torch.float64
        )
    )
    K = intrinsics_from_fov(80.0, 48, 64)
    out = ExactRenderer(scene).render(pose, K, 48, 64)
    expected = _analytic_room_depth(size, pose, K, 48, 64)
    assert out.mask.all()
    np.testing.assert_allclose(out.depth[0, 0].numpy(), expected, rtol=1e-4)


def test_checker_quad_colours_at_chosen_pixels() -> None:
    scene = _quad_scene()
    pose = look_at(torch.tensor([0.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, 1.0])).double()
    height = width = 64
    K = intrinsics_from_fov(60.0, height, width)
    out = ExactRenderer(scene, FLAT).render(pose, K, height, width)
    _, dirs = pixel_rays(pose, K, height, width)
    hit = dirs.reshape(height, width, 3).numpy() * 2.0  # ray parameter = z-depth = 2 on the quad
    u, v = (hit[..., 0] + 1) / 2, (hit[..., 1] + 1) / 2
    inside = (u > 0) & (u < 1) & (v > 0) & (v < 1)
    cell_u, cell_v = u * 4, (1 - v) * 4  # v = 1 is the top image row of the texture
    away_from_edges = (np.abs(cell_u - np.round(cell_u)) > 0.2) & (np.abs(cell_v - np.round(cell_v)) > 0.2)
    chosen = np.argwhere(inside & away_from_edges)
    assert len(chosen) > 500
    rgb = out.rgb[0].permute(1, 2, 0).numpy()
    for row, col in chosen:
        parity = (int(cell_v[row, col]) + int(cell_u[row, col])) % 2
        np.testing.assert_allclose(rgb[row, col], RED if parity == 0 else BLUE, atol=1e-6)


def test_missed_rays_have_false_mask_zero_depth_background_colour() -> None:
    scene = _quad_scene()
    pose = look_at(torch.tensor([0.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, 1.0])).double()
    out = ExactRenderer(scene, FLAT).render(pose, intrinsics_from_fov(120.0, 32, 32), 32, 32)
    assert not bool(out.mask[0, 0, 0, 0]) and float(out.depth[0, 0, 0, 0]) == 0.0
    assert torch.allclose(out.rgb[0, :, 0, 0], torch.tensor([0.25, 0.5, 0.75]))
    assert int(out.triangle_ids[0, 0, 0, 0]) == -1
    assert bool(out.mask[0, 0, 16, 16]) and float(out.depth[0, 0, 16, 16]) == pytest.approx(2.0)
    assert (out.depth[~out.mask] == 0).all() and (out.depth[out.mask] > 0).all()


def test_alpha_mask_lets_rays_through_to_the_surface_behind() -> None:
    opacity = np.zeros((32, 32), np.float32)
    opacity[:, 16:] = 1.0  # u > 0.5 opaque; seen from behind, u = 1 is on the image's left
    scene = _quad_scene(opacity=opacity, wall_behind=True)
    pose = look_at(torch.tensor([0.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, 1.0])).double()
    out = ExactRenderer(scene, FLAT).render(pose, intrinsics_from_fov(40.0, 32, 32), 32, 32)
    assert float(out.depth[0, 0, 16, 27]) == pytest.approx(4.0, rel=1e-5)  # through the transparent half
    assert torch.allclose(out.rgb[0, :, 16, 27], torch.tensor([0.0, 1.0, 0.0]))
    assert float(out.depth[0, 0, 16, 4]) == pytest.approx(2.0, rel=1e-5)  # stopped by the opaque half


@pytest.mark.parametrize("backend", ["open3d", "warp"])
def test_first_opaque_hit_behind_transparent_texels_is_the_nearest_of_all_intersections(backend: str) -> None:
    # alpha-masked quads (checkered holes) in front of, between and behind opaque quads, and a wall.
    # Open3D's hits pass the masks in torch; Warp's in its traversal kernel, checked here against
    # the intersections it lists and the masks read in torch
    holes = (np.indices((32, 32)).sum(0) // 8 % 2).astype(np.float32)
    materials = [
        Material("leaf", base_color=np.ones(3), texture=_checker_texture(), opacity=holes),
        Material("wall", base_color=np.array([0.0, 1.0, 0.0])),
    ]

    def quad(z: float, half: float, shift: float, material: int):
        corners = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], float)
        return quad_part(corners + [shift, 0.0, 0.0], material, f"quad{z}")

    scene = assemble_scene(
        [
            quad(2.0, 1.0, 0.0, 0),
            quad(2.5, 0.4, 0.3, 1),
            quad(3.0, 1.0, 0.1, 0),
            quad(3.5, 1.0, -0.2, 0),
            quad(4.0, 5.0, 0.0, 1),
        ],
        materials,
        name="leaves",
    )
    renderer = ExactRenderer(scene, backend=backend)
    assert renderer.caster.applies_alpha_masks == (backend == "warp")
    directions = np.c_[np.random.default_rng(0).uniform(-0.6, 0.6, (4000, 2)), np.ones(4000)]
    origins = np.zeros_like(directions)
    hits = renderer.cast(origins, directions)
    ray_ids, t, ids, bary = (x.numpy() for x in renderer.intersections(origins, directions))
    first = np.r_[True, ray_ids[1:] != ray_ids[:-1]]
    assert len(np.unique(ids[first])) >= 6  # rays stop on every layer (two triangles a quad)
    hits = hits.numpy()
    np.testing.assert_array_equal(np.flatnonzero(hits.hit), ray_ids[first])
    np.testing.assert_array_equal(hits.t[ray_ids[first]], t[first])
    np.testing.assert_array_equal(hits.triangle_ids[ray_ids[first]], ids[first])
    np.testing.assert_array_equal(hits.barycentrics[ray_ids[first]], bary[first])


def _same_point_from_two_cameras(scene) -> tuple[torch.Tensor, torch.Tensor]:
    renderer = ExactRenderer(scene)
    camera = scene.cameras[0]
    first = renderer.render(camera.world_T_cam, camera.intrinsics(5, 5), 5, 5)
    point = first.points[0, :, 2, 2].double()
    other_eye = camera.world_T_cam[:3, 3] + torch.tensor([0.4, -0.3, 0.5], dtype=torch.float64)
    second = renderer.render(look_at(other_eye, point), camera.intrinsics(5, 5), 5, 5)
    assert torch.allclose(second.points[0, :, 2, 2].double(), point, atol=1e-4)
    return first.rgb[0, :, 2, 2], second.rgb[0, :, 2, 2]


def test_shading_is_view_independent() -> None:
    scene = box_room(seed=0)
    for material in scene.materials:  # constant colours: only the shading model is tested
        material.texture = None
    first, second = _same_point_from_two_cameras(scene)
    assert torch.allclose(first, second, atol=1e-6)


def test_texture_prefiltering_changes_colour_only_slightly(room) -> None:
    # mip-mapping blurs a texture by the footprint, which depends on distance: the one, bounded,
    # view dependence of a surface point's colour
    first, second = _same_point_from_two_cameras(room)
    assert float((first - second).abs().max()) < 0.01


def test_normals_face_the_camera_and_shapes(room) -> None:
    camera = room.cameras[0]
    out = ExactRenderer(room).render(camera.world_T_cam, camera.intrinsics(24, 32), 24, 32)
    assert out.rgb.shape == (1, 3, 24, 32) and out.depth.shape == (1, 1, 24, 32)
    assert out.rgb.dtype == torch.float32 and out.depth.dtype == torch.float32
    view = out.points - camera.world_T_cam[:3, 3].float()[None, :, None, None]
    assert ((out.normals * view).sum(dim=1) < 0).all()


def test_batch_equals_separate_renders_and_supersampling(room) -> None:
    renderer = ExactRenderer(room)
    camera = room.cameras[0]
    moved = camera.world_T_cam.clone()
    moved[0, 3] += 0.3
    poses = torch.stack([camera.world_T_cam, moved])
    K = camera.intrinsics(20, 30)
    batch = renderer.render(poses, K, 20, 30)
    for index in range(2):
        single = renderer.render(poses[index], K, 20, 30)
        assert torch.equal(batch.rgb[index], single.rgb[0]) and torch.equal(batch.depth[index], single.depth[0])
    ss = renderer.render(poses, K, 20, 30, supersample=4)
    assert torch.equal(ss.depth, batch.depth)
    assert 0 < float((ss.rgb - batch.rgb).abs().mean()) < 0.1


@pytest.mark.parametrize("bad", ["nan", "scale"])
def test_bad_pose_raises(room, bad: str) -> None:
    pose = room.cameras[0].world_T_cam.clone()
    if bad == "nan":
        pose[0, 3] = float("nan")
    else:
        pose[:3, :3] *= 2
    with pytest.raises(ValueError, match=r"NaN|not a rotation"):
        ExactRenderer(room).render(pose, intrinsics_from_fov(60.0, 4, 4), 4, 4)


def test_a_view_renders_the_same_alone_as_beside_a_view_of_another_field_of_view() -> None:
    """A pixel's footprint filters its textures: views of different fields of view in one batch
    are each filtered at their own, so a batch's make-up changes no view's pixels."""
    renderer = ExactRenderer(box_room(seed=0))
    pose = renderer.scene.cameras[0].world_T_cam
    wide, narrow = intrinsics_from_fov(100.0, 24, 32), intrinsics_from_fov(40.0, 24, 32)
    together = renderer.render(torch.stack([pose, pose]), torch.stack([wide, narrow]), 24, 32, supersample=2)
    for b, K in enumerate((wide, narrow)):
        alone = renderer.render(pose[None], K, 24, 32, supersample=2)
        assert torch.equal(together.rgb[b], alone.rgb[0]) and torch.equal(together.depth[b], alone.depth[0])
    # the footprint matters: the narrow view's rays shaded at the wide one's footprint are another image
    origins, directions = pixel_rays(pose, narrow, 24, 32)
    rays = (origins.reshape(-1, 3), directions.reshape(-1, 3))
    own, other = (renderer.cast_and_shade(*rays, pixel_angle(K), True, False)[1]["rgb"] for K in (narrow, wide))
    assert not torch.equal(own, other)
