"""Scan-like rooms: a generated room's bake stored per vertex on a reconstruction-like mesh, written
in ScanNet's, ARKitScenes', Replica's and Matterport3D's layouts and read back by the loaders."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import kadv
from kadv.datasets.scan_rooms import SCAN_LAYOUTS, ScanLike, scan_like, write_scan
from kadv.render import ExactRenderer, Shading
from kadv.scenes.textures import srgb_to_linear

MAGENTA = (1.0, 0.0, 1.0)  # the background a miss shows here, unlike any captured colour


@pytest.fixture(scope="module")
def scan() -> ScanLike:
    return scan_like(kadv.box_room(seed=0), seed=0)


@pytest.fixture(scope="module")
def written(scan: ScanLike, tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("scans")
    return {layout: write_scan(scan, folder, layout) for layout in SCAN_LAYOUTS}


def test_a_scan_like_is_irregular_holed_open_above_and_wound_at_random(scan: ScanLike) -> None:
    room = scan.source
    assert len(scan.faces) > 20 * room.num_triangles  # re-meshed small
    edges = np.linalg.norm(scan.vertices[scan.faces] - scan.vertices[np.roll(scan.faces, 1, axis=1)], axis=2)
    assert np.percentile(edges, 99) < 0.2 and np.std(edges) > 0.01  # small, and not a regular grid
    assert len(scan.missing_ceiling) >= 1
    normals = np.cross(*(scan.vertices[scan.faces][:, k] - scan.vertices[scan.faces][:, 0] for k in (1, 2)))
    up_facing = normals[:, 1] > 0.9 * np.linalg.norm(normals, axis=1)  # floor triangles wound upwards
    floor = scan.vertices[scan.faces][:, :, 1].mean(axis=1) < 0.05
    share = up_facing[floor].mean()
    assert 0.3 < share < 0.7  # neither winding can be trusted


@pytest.mark.parametrize("layout", list(SCAN_LAYOUTS))
def test_every_layout_loads_back_z_up_in_metres_as_the_room_was(layout: str, scan, written) -> None:
    loaded = kadv.load_scene(written[layout])
    assert loaded.scan is not None and loaded.num_triangles == len(scan.faces)
    # the scans are Z-up in metres: loaded into kadv's y-up world, the room is where it was
    np.testing.assert_allclose(loaded.bounds, scan.source.bounds, atol=0.05)
    if layout != "matterport":  # each corner has its vertex's colour, decoded once to linear light
        expected = srgb_to_linear(scan.colors / 255.0).astype(np.float32)[loaded.faces]
        np.testing.assert_allclose(loaded.colors, expected, atol=1e-6)
    else:  # atlases: one texture per atlas, read from the OBJ's material library
        assert loaded.colors is None and all(m.texture is not None for m in loaded.materials)


@pytest.mark.parametrize("layout", list(SCAN_LAYOUTS))
def test_rendered_as_scanned_a_scan_like_agrees_with_the_baked_room_away_from_its_holes(layout, scan, written):
    room = scan.source
    baked = ExactRenderer(room, Shading(lighting="baked", reflections=False), progress=False)
    scanned = ExactRenderer(kadv.load_scene(written[layout]), Shading(lighting="scanned", background=MAGENTA))
    camera = room.cameras[0]
    K = kadv.intrinsics_from_fov(camera.fov_x_deg, 96, 128)
    source = baked.render(camera.world_T_cam[None], K, 96, 128, supersample=2)
    ours = scanned.render(camera.world_T_cam[None], K, 96, 128, supersample=2)
    seen = ours.mask[0, 0] & source.mask[0, 0]
    psnr = -10 * torch.log10(((source.rgb - ours.rgb) ** 2).mean(1)[0][seen].mean())
    # measured 24.2 dB (ScanNet's layout, 240x320): the per-vertex colour of 10 cm triangles blurs the textures
    assert psnr > 20.0, f"{layout}: {float(psnr):.1f} dB"


def test_the_missing_ceiling_is_a_miss_in_the_mask_with_no_depth_and_the_background(scan, written) -> None:
    scanned = ExactRenderer(kadv.load_scene(written["scannet"]), Shading(lighting="scanned", background=MAGENTA))
    x, y, z, _ = max(scan.missing_ceiling, key=lambda patch: patch[3])  # the widest patch's centre
    eye = torch.tensor([x, y - 1.2, z])
    up = kadv.look_at(eye, eye + torch.tensor([0.0, 1.0, 0.01]))
    out = scanned.render(up[None], kadv.intrinsics_from_fov(20.0, 16, 16), 16, 16)
    centre = (slice(None), slice(None), slice(6, 10), slice(6, 10))
    assert not out.mask[centre].any() and (out.depth[centre] == 0).all()
    torch.testing.assert_close(out.rgb[centre], torch.tensor(MAGENTA)[None, :, None, None].expand(1, 3, 4, 4))


def test_an_attack_on_a_scan_like_in_scannets_layout_chooses_only_valid_views(written) -> None:
    from kadv.attack import AttackConfig, attack
    from kadv.testing.options import CheckOptions, setup

    built = setup("kadv_tiny", str(written["scannet"]), CheckOptions(lighting="scanned", size=(48, 64)))
    assert built.renderer.shading.lighting == "scanned" and len(built.views) == 2  # drawn in its free space
    config = AttackConfig(budget_passes=16, envelope="upright")
    result = attack(built.objective, built.differentiable, built.views, *built.size, config, 0, progress=False)
    for view in result.views:
        assert view.top and all(r.valid for r in view.top) and all(r.valid for r in view.path[1:])
        assert min(r.delta1 for r in view.top) < view.init_record.delta1
    verdicts = {r.verdict for view in result.views for r in view.records}
    assert "valid" in verdicts


def test_pose_gradients_on_a_scan_like_pass_the_gradient_check_away_from_occlusions(written) -> None:
    """The gradient check's interior thresholds on a scan rendered as scanned; its full functionals
    are left out: a scan's floaters, holes and noise put small occlusions everywhere, and their
    finite-difference reference does not agree with itself at half the step."""
    from kadv.diagnostics import gradient_check_poses
    from kadv.render import DiffRenderConfig

    renderer = ExactRenderer(kadv.load_scene(written["scannet"]), Shading(lighting="scanned"))
    interior = ("rgb_interior", "depth_interior")
    checks = gradient_check_poses(
        renderer, 3, 0, 70.0, 48, 64, {"default": DiffRenderConfig()}, trusted=interior, edge_jump=0.02
    )
    scores = np.array([[c.score(f) for f in interior] for c in checks["default"]])
    assert np.median(scores[:, 0]) >= 0.99 and np.median(scores[:, 1]) >= 0.99, scores
