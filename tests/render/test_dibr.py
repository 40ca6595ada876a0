"""kadv.render.dibr: the anchor warped into the current view, against analytic planes."""

from __future__ import annotations

import torch

from kadv.geometry import intrinsics_from_fov, look_at, perturb_world_T_cam
from kadv.render import ExactRenderer, dibr, render_anchor, reproject
from kadv.render.layers import camera_face_normals
from kadv.scenes import box_room

H, W = 24, 32


def _wall_view() -> tuple[ExactRenderer, torch.Tensor, torch.Tensor]:
    """A camera 1.5 m in front of the box room's wall x = 0, looking straight at it; nothing else in view."""
    renderer = ExactRenderer(box_room(seed=0))
    eye = torch.tensor([1.5, 1.4, 1.8], dtype=torch.float64)
    return (
        renderer,
        look_at(eye, eye - torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)).double()[None],
        intrinsics_from_fov(40.0, H, W),
    )


def _warp(renderer: ExactRenderer, anchor_pose: torch.Tensor, pose: torch.Tensor, K: torch.Tensor):
    anchor = render_anchor(renderer, anchor_pose, K, H, W, guard_band=4, supersample=2)
    exact = renderer.render(pose.detach(), K, H, W)
    normals = camera_face_normals(renderer.surfaces, exact.triangle_ids[:, 0], pose).permute(0, 3, 1, 2)
    return exact, reproject(anchor, exact.depth, normals, torch.linalg.inv(anchor.world_T_cam) @ pose, K)


def test_the_anchor_at_the_current_pose_is_reproduced() -> None:
    renderer, pose, K = _wall_view()
    exact, warp = _warp(renderer, pose, pose, K)
    assert bool(warp.valid.all())
    torch.testing.assert_close(warp.depth, exact.depth, rtol=1e-5, atol=0)
    assert float((warp.layer == 0).float().mean()) == 1.0


def test_after_a_move_the_warped_depth_is_the_new_exact_depth() -> None:
    renderer, anchor_pose, K = _wall_view()
    moved = perturb_world_T_cam(
        anchor_pose,
        torch.tensor([[0.0, 0.03, 0.0]], dtype=torch.float64),
        torch.tensor([[-0.2, 0.05, 0.1]], dtype=torch.float64),
    )
    exact, warp = _warp(renderer, anchor_pose, moved, K)
    assert float(warp.valid.float().mean()) > 0.9
    valid = warp.valid
    torch.testing.assert_close(warp.depth[valid], exact.depth[valid], rtol=1e-4, atol=0)


def test_moving_toward_a_frontal_wall_lowers_every_depth_one_for_one() -> None:
    """d(depth)/d(offset along the optical axis) = -1 on a wall the camera faces squarely."""
    renderer, pose, K = _wall_view()
    axis = pose[0, :3, 2]
    step = torch.zeros(1, 3, dtype=torch.float64, requires_grad=True)
    current = perturb_world_T_cam(pose, torch.zeros(1, 3, dtype=torch.float64), step * axis)
    _, warp = _warp(renderer, pose, current, K)
    depth = warp.depth[warp.valid]
    (gradient,) = torch.autograd.grad(depth.double().mean(), step)
    assert abs(float(gradient.sum()) + 1.0) < 1e-3


def test_pixels_without_a_surface_stay_invalid() -> None:
    renderer, pose, K = _wall_view()
    anchor = render_anchor(renderer, pose, K, H, W, guard_band=4, supersample=2)
    exact = renderer.render(pose, K, H, W)
    depth = exact.depth.clone()
    depth[..., :4, :] = 0.0  # as if these rays had missed
    normals = camera_face_normals(renderer.surfaces, exact.triangle_ids[:, 0], pose).permute(0, 3, 1, 2)
    warp = reproject(anchor, depth, normals, torch.eye(4, dtype=torch.float64)[None], K)
    assert not bool(warp.valid[..., :4, :].any()) and bool(warp.valid[..., 4:, :].all())
    assert float(warp.depth[..., :4, :].abs().max()) == 0.0


def test_at_the_anchor_pose_the_lean_warp_reads_the_closed_form_values_and_slopes() -> None:
    """At A = P the closed form reads each sub-sample on its own pixel centre; the lean warp reads
    the box-filtered anchor once per pixel. Where both hold, on a view with occlusion edges, the
    colours are the same box means, the lean warp's depth is the exact one it was tested against,
    and the pose gradients (central differences of the same box-filtered image) point the same way.
    At 48 x 64: coarser, most pixels lie by a crease or an edge, where the two reads' taps differ."""
    height, width = 48, 64
    renderer = ExactRenderer(box_room(seed=0))
    pose, K = renderer.scene.cameras[0].world_T_cam.double()[None], intrinsics_from_fov(60.0, height, width)
    anchor = render_anchor(renderer, pose, K, height, width, guard_band=1, supersample=2)
    exact = renderer.render(pose, K, height, width)
    normals = camera_face_normals(renderer.surfaces, exact.triangle_ids[:, 0], pose).permute(0, 3, 1, 2)
    weights = torch.linspace(-1.0, 1.0, 4 * height * width, dtype=torch.float64).reshape(1, 4, height, width)
    results = []
    for warp_of in (
        lambda A_T_P: reproject(anchor, exact.depth, normals, A_T_P, K),
        lambda A_T_P: dibr.warp_boxed(anchor.boxed, exact.depth, normals, A_T_P, K),
    ):
        params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
        current = perturb_world_T_cam(pose, params[:, :3], params[:, 3:])
        warp = warp_of(torch.linalg.inv(anchor.world_T_cam) @ current)
        both = results[0][0].valid & warp.valid if results else warp.valid
        (torch.cat([warp.rgb, warp.depth], 1).double() * weights * both).sum().backward()
        results.append((warp, params.grad))
    (closed, closed_grad), (lean, lean_grad) = results
    both = closed.valid & lean.valid
    assert 0.5 < float(both.float().mean()) < 1.0  # edges in view, some pixels left to the silhouettes
    assert float(both.sum()) >= 0.95 * float(closed.valid.sum())
    torch.testing.assert_close(lean.rgb * both, closed.rgb * both, rtol=0, atol=1e-5)
    torch.testing.assert_close(lean.depth[lean.valid], exact.depth[lean.valid], rtol=1e-6, atol=0)  # the cast's
    cosine = torch.nn.functional.cosine_similarity(lean_grad, closed_grad, dim=1)
    assert float(cosine) > 0.99, float(cosine)


def test_without_a_gradient_a_moved_view_reads_what_it_reads_with_one() -> None:
    """Under no_grad the warp maps each pixel's point to the anchor as a rigid transform and reads
    it once; with a gradient the point meets its surface's plane and the diagonal means are read too,
    which shape only the gradient: the pixels that hold and the values they read are the same (to
    float32 rounding)."""
    renderer = ExactRenderer(box_room(seed=0))
    pose, K = renderer.scene.cameras[0].world_T_cam.double()[None], intrinsics_from_fov(60.0, H, W)
    moved = perturb_world_T_cam(
        pose,
        torch.tensor([[0.01, -0.02, 0.0]], dtype=torch.float64),
        torch.tensor([[0.03, 0.0, -0.05]], dtype=torch.float64),
    )
    anchor = render_anchor(renderer, pose, K, H, W, guard_band=4, supersample=2)
    exact = renderer.render(moved, K, H, W)
    normals = camera_face_normals(renderer.surfaces, exact.triangle_ids[:, 0], moved).permute(0, 3, 1, 2)
    A_T_P = torch.linalg.inv(pose) @ moved
    with torch.no_grad():
        plain = dibr.warp_boxed(anchor.boxed, exact.depth, normals, A_T_P, K)
    graded = dibr.warp_boxed(anchor.boxed, exact.depth, normals, A_T_P.clone().requires_grad_(True), K)
    assert float(plain.valid.float().mean()) > 0.8
    assert torch.equal(plain.valid, graded.valid)
    torch.testing.assert_close(plain.rgb, graded.rgb.detach(), rtol=0, atol=1e-4)
    torch.testing.assert_close(plain.depth, graded.depth.detach(), rtol=1e-6, atol=0)


def test_the_closed_form_taps_are_the_same_in_bands_as_at_once(monkeypatch) -> None:
    """The CPU computes the taps in bands of rows, a GPU the batch at once: the rows' arithmetic is
    the same either way, so values and gradients are equal bit for bit."""
    renderer = ExactRenderer(box_room(seed=0))
    pose, K = renderer.scene.cameras[0].world_T_cam.double()[None], intrinsics_from_fov(60.0, H, W)
    anchor = render_anchor(renderer, pose, K, H, W, guard_band=1, supersample=2)
    exact = renderer.render(pose, K, H, W)
    normals = camera_face_normals(renderer.surfaces, exact.triangle_ids[:, 0], pose).permute(0, 3, 1, 2)
    results = []
    for samples in (10**9, 5 * 2 * W):  # one band; bands of 5 hi-res rows (the last one shorter)
        monkeypatch.setattr(dibr, "_BAND_SAMPLES", samples)
        params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
        current = perturb_world_T_cam(pose, params[:, :3], params[:, 3:])
        warp = reproject(anchor, exact.depth, normals, torch.linalg.inv(anchor.world_T_cam) @ current, K)
        (torch.cat([warp.rgb, warp.depth], 1).double().sum()).backward()
        results.append((warp.rgb, warp.depth, warp.valid, params.grad))
    for whole, banded in zip(*results):
        assert torch.equal(whole, banded)
