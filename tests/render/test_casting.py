"""The Warp ray-casting backend against Open3D's, on Warp's CPU device: same depth, hits, colours
and distances on the box room, a generated room and the shared scenes."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from kadv.geometry import intrinsics_from_fov
from kadv.geometry.camera import pixel_rays
from kadv.penalties import distance_to_surface, random_valid_poses
from kadv.render import ExactRenderer, Shading
from kadv.render.backends import make_caster, resolve_backend
from kadv.scenes import box_room, procedural_room
from tests.conftest import REAL_SCENES, cached_real_scene

HEIGHT, WIDTH = 48, 64
# Warp's caster on every device this machine has: its CPU device, and CUDA where present
WARP_DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _scene(name: str):
    if name == "box_room":
        return box_room(seed=0)
    if name == "procedural":
        return procedural_room(seed=3)
    return cached_real_scene(name)


@pytest.mark.parametrize("device", WARP_DEVICES)
@pytest.mark.parametrize("name", ["box_room", "procedural", *REAL_SCENES])
def test_warp_renders_and_distances_equal_open3d(name: str, device: str) -> None:
    scene = _scene(name)
    open3d = ExactRenderer(scene, Shading(), backend="open3d")
    warp = ExactRenderer(scene, Shading(), backend="warp", device=device)
    camera = scene.cameras[0]
    poses = torch.cat([camera.world_T_cam[None], random_valid_poses(open3d, 3, np.random.default_rng(0), 70.0)])
    K = intrinsics_from_fov(70.0, HEIGHT, WIDTH)
    a, b = (r.render(poses, K, HEIGHT, WIDTH).to("cpu") for r in (open3d, warp))
    assert (a.mask == b.mask).float().mean() >= 0.999
    both = a.mask & b.mask
    same_ids = a.triangle_ids == b.triangle_ids
    # where coplanar triangles overlap (z-fighting: a generated room's trim on its wall) or a ray
    # meets a shared edge, either is the first hit: Embree and Warp break the tie differently
    normals = [torch.from_numpy(scene.face_normals)[out.triangle_ids.clamp_min(0)[:, 0]] for out in (a, b)]
    parallel = ((normals[0] * normals[1]).sum(-1).abs() > 0.9999)[:, None]  # (B, 1, H, W)
    tied = both & ((a.depth - b.depth).abs() <= 1e-6 * a.depth) & parallel
    assert (same_ids | tied).float().mean() >= 0.999
    assert same_ids.float().mean() >= 0.998
    relative = ((a.depth - b.depth).abs() / a.depth.clamp_min(1e-9))[both]
    assert float(relative.median()) <= 1e-6
    assert float(relative.max()) <= 1e-4
    close = ((a.rgb - b.rgb).abs() <= 2 / 255).all(dim=1)
    assert close.float().mean() >= 0.99
    centres = poses[:, :3, 3]
    assert torch.allclose(distance_to_surface(open3d, centres), distance_to_surface(warp, centres).cpu(), atol=1e-5)


def test_warp_lists_every_hit_along_a_ray_through_a_closed_box() -> None:
    room = box_room(seed=0, size=(4.0, 3.0, 5.0), num_boxes=0)  # x 0-4, y 0-3, z 0-5
    caster = make_caster(room.vertices, room.faces, "warp")
    origins = torch.tensor([[-1.0, 1.5, 2.5], [2.0, 1.5, 2.5]])
    directions = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    ray_ids, t, _, _ = caster.all_hits(origins, directions)
    # the first ray enters at x = 0 and leaves at x = 4; the second starts inside and meets z = 5
    assert sorted(t[ray_ids == 0].tolist()) == pytest.approx([1.0, 5.0], abs=1e-5)
    assert t[ray_ids == 1].tolist() == pytest.approx([2.5], abs=1e-5)
    t_first, ids_first, bary_first = caster.first_hits(origins, directions)
    assert t_first.tolist() == pytest.approx([1.0, 2.5], abs=1e-5)
    # Open3D's barycentric convention: the hit is (1 - u - v) a + u b + v c
    corners = torch.from_numpy(room.vertices[room.faces[ids_first.numpy()]]).float()
    u, v = bary_first[:, :1], bary_first[:, 1:]
    hit = (1 - u - v) * corners[:, 0] + u * corners[:, 1] + v * corners[:, 2]
    assert torch.allclose(hit, origins + t_first[:, None] * directions, atol=1e-5)


def test_backend_choice_and_bad_names() -> None:
    assert resolve_backend("auto", "cpu") == "open3d"
    assert resolve_backend("warp", "cpu") == "warp"
    with pytest.raises(ValueError, match=r"render\.backend must be one of auto, open3d, warp, got .bogus."):
        resolve_backend("bogus")


def test_importing_kadv_does_not_import_warp() -> None:
    code = "import sys, kadv, kadv.render; kadv.ExactRenderer(kadv.box_room(seed=0)); print('warp' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "False\n"


def test_textures_too_large_for_memory_are_refused_with_the_figures(monkeypatch) -> None:
    from kadv.render import surface

    room = box_room(seed=0)
    needed = surface.pyramid_bytes(room)
    texels = sum(m.texture.size for m in room.materials if m.texture is not None)
    assert needed >= 4 * texels * 4 // 3 > 0  # float32, and the mip levels below the full size
    monkeypatch.setattr(surface, "free_memory", lambda device: needed - 1)
    with pytest.raises(
        ValueError, match=rf"scene 'box_room_0': its texture pyramids need about {needed / 2**20:.0f} MiB"
    ):
        ExactRenderer(room)
    monkeypatch.setattr(surface, "free_memory", lambda device: needed)
    built = ExactRenderer(room).surfaces.materials.atlas.texels
    assert 0 < built.numel() * built.element_size() <= needed  # the estimate covers what is built


def test_a_scene_too_large_for_the_device_is_refused_with_the_figures(monkeypatch) -> None:
    from kadv.render import warp_caster

    room = box_room(seed=0)
    monkeypatch.setattr(warp_caster, "free_memory", lambda device: 1024)
    with pytest.raises(ValueError, match=rf"scene: {room.num_triangles} triangles need about .* MiB of cpu memory"):
        make_caster(room.vertices, room.faces, "warp")


def test_an_open3d_cast_of_some_live_rays_is_the_full_cast_with_the_others_missing() -> None:
    """Open3D's caster casts only the live rays (a depth peel's later casts have few): each live
    ray's hit is the one a cast of every ray gives, and the others are misses."""
    renderer = ExactRenderer(box_room(seed=0), backend="open3d")
    camera = renderer.scene.cameras[0]
    origins, directions = (
        rays.reshape(-1, 3).float()
        for rays in pixel_rays(
            camera.world_T_cam[None].double(), intrinsics_from_fov(70.0, HEIGHT, WIDTH), HEIGHT, WIDTH
        )
    )
    live = torch.from_numpy(np.random.default_rng(0).uniform(size=len(origins)) < 0.2)
    t_all, ids_all, bary_all = renderer.caster.first_hits(origins, directions)
    t, ids, bary = renderer.caster.first_hits(origins, directions, live)
    assert int((ids_all[live] >= 0).sum()) > 0.9 * int(live.sum())
    assert torch.equal(t[live], t_all[live]) and torch.equal(ids[live], ids_all[live])
    assert torch.equal(bary[live], bary_all[live])
    assert bool(torch.isinf(t[~live]).all()) and bool((ids[~live] == -1).all()) and float(bary[~live].abs().max()) == 0
    none = renderer.caster.first_hits(origins, directions, torch.zeros_like(live))
    assert bool((none[1] == -1).all())
