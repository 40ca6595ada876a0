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
    assert loaded.captured_by is not None and loaded.num_triangles == len(scan.faces)
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


@pytest.fixture(scope="module")
def partial(tmp_path_factory) -> dict[float, dict[str, Path]]:
    """The box room's scan-like cut at 1.2 and 1.6 m above the floor with its wall at x+ left out, in
    ScanNet's layout aligned (the room's frame) and without its .txt (the sensor's frame: turned 30
    degrees), and the uncut scan-like."""
    from kadv.datasets.scan_rooms import ScanLikeSettings

    room, out = kadv.box_room(seed=0), {}
    for cut in (1.2, 1.6):
        scan = scan_like(room, seed=0, settings=ScanLikeSettings(cut_height=cut, missing_walls=("x+",)))
        aligned = write_scan(scan, tmp_path_factory.mktemp(f"cut{cut}"), "scannet")
        raw = write_scan(scan, tmp_path_factory.mktemp(f"raw{cut}"), "scannet")
        raw.with_name("scene0000_00.txt").unlink()
        out[cut] = {"aligned": aligned, "raw": raw}
    return out


def test_a_cut_scan_keeps_nothing_above_its_cut_nor_its_missing_wall(partial) -> None:
    room = kadv.box_room(seed=0)
    for cut, files in partial.items():
        scene = kadv.load_scene(files["aligned"])
        hi = scene.bounds[1]
        assert hi[1] <= room.camera_region[0, 1] + cut + 0.02  # the noise's few millimetres
        corners = scene.vertices[scene.faces]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        facing_x = np.abs(normal[:, 0]) > 0.9 * np.linalg.norm(normal, axis=1)
        at_wall = np.abs(corners[:, :, 0].mean(axis=1) - room.camera_region[1, 0]) < 0.05
        assert not (facing_x & at_wall).any()  # the wall at x+ is gone
        assert len(np.unique(scene.faces)) == len(scene.vertices)  # what was cut left no vertex behind


def test_a_partial_scan_judges_views_as_the_whole_scan_does_and_views_beyond_it_outside(partial, written) -> None:
    """Views whose centre and 70% of whose pixels lie below the cut: the cut scan's verdicts agree
    with the uncut scan's on at least 90% of them (98.1%, 98.9% measured at 1.2 and 1.6 m on 600)."""
    import collections

    from kadv.penalties import PenaltyConfig, view_validity

    room = kadv.box_room(seed=0)
    options, K = PenaltyConfig().validity_options(), kadv.intrinsics_from_fov(70.0, 48, 64)
    whole = ExactRenderer(kadv.load_scene(written["scannet"]), Shading(lighting="scanned"))
    source = ExactRenderer(room)
    box = room.camera_region
    for cut, files in partial.items():
        renderer = ExactRenderer(kadv.load_scene(files["aligned"]), Shading(lighting="scanned"))
        rng = np.random.default_rng(0)
        high = box[1] - 0.2
        high[1] = box[0, 1] + cut - 0.05
        eyes = torch.from_numpy(rng.uniform(box[0] + 0.2, high, (400, 3)))
        poses = kadv.look_at(eyes, eyes + torch.from_numpy(rng.normal(size=(400, 3)) * [1.0, 0.2, 1.0]))
        out = source.render(poses, K, 48, 64)
        below = ((out.points[:, 1] < box[0, 1] + cut) & out.mask[:, 0]).sum(dim=(1, 2))
        kept = (below >= 0.7 * out.mask[:, 0].sum(dim=(1, 2))).tolist()
        theirs = view_validity(whole, poses, K, 48, 64, **options).verdicts
        ours = view_validity(renderer, poses, K, 48, 64, **options).verdicts
        pairs = collections.Counter((a, b) for a, b, k in zip(theirs, ours, kept) if k)
        agree = sum(n for (a, b), n in pairs.items() if a == b)
        assert agree >= 0.9 * sum(pairs.values()), (cut, pairs)
        # above its top, beyond its bounds: outside; looking over its walls is no hole
        above = kadv.look_at(torch.tensor([[2.0, cut + 0.3, 1.8]]), torch.tensor([[4.0, cut, 1.8]]))
        beyond = kadv.look_at(torch.tensor([[7.0, 0.8, 1.8]]), torch.tensor([[3.0, 0.8, 1.8]]))
        verdicts = view_validity(renderer, torch.cat([above, beyond]), K, 48, 64, **options)
        assert verdicts.verdicts == ["outside the scene"] * 2
        over = kadv.look_at(torch.tensor([[1.5, cut - 0.3, 1.8]]), torch.tensor([[4.0, cut + 0.5, 1.8]]))
        seen = view_validity(renderer, over, K, 48, 64, **options)
        assert float(seen.past_top_fraction[0]) > 0.2 and float(seen.hole_fraction[0]) < 0.05


def test_an_attack_on_a_partial_scan_in_its_sensors_frame_runs_from_views_under_its_top(partial) -> None:
    from kadv.attack import AttackConfig, attack
    from kadv.testing.options import CheckOptions, setup

    for cut, files in partial.items():
        built = setup("kadv_tiny", str(files["raw"]), CheckOptions(lighting="scanned", size=(48, 64)))
        top = built.renderer.scene.bounds[1, 1]
        assert len(built.views) == 2 and all(float(v.world_T_cam[1, 3]) < top for v in built.views), cut
        result = attack(built.objective, built.differentiable, built.views, *built.size,
                        AttackConfig(budget_passes=16), 0, progress=False)  # fmt: skip
        for view in result.views:
            assert view.top and all(r.valid for r in view.top)


def test_a_scan_with_no_init_view_is_refused_in_one_line_with_what_was_dropped_and_what_to_set(tmp_path) -> None:
    from kadv.attack import InitViewConfig, InitViewError, PenaltyConfig, sample_init_views
    from kadv.datasets.scan_rooms import ScanLikeSettings

    # cut at 0.3 m: no eye height fits under its top
    scan = scan_like(kadv.box_room(seed=0), seed=0, settings=ScanLikeSettings(cut_height=0.3))
    renderer = ExactRenderer(kadv.load_scene(write_scan(scan, tmp_path, "arkitscenes")), Shading(lighting="scanned"))
    model = kadv.load_model("kadv_tiny")
    with pytest.raises(InitViewError) as error:
        sample_init_views(renderer, model, 2, 0, InitViewConfig(), PenaltyConfig(), 24, 32)
    message = str(error.value)
    assert "\n" not in message and "only 0 of 2 sampled init views are valid (drew " in message
    assert "with no room for the eye height under the scene's top" in message
    assert "init.eye_height" in message and "init.params" in message
