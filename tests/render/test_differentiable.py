from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.geometry import intrinsics_from_fov
from kadv.penalties import random_valid_poses
from kadv.render import DifferentiableRenderer, DiffRenderConfig, ExactRenderer

K_SMALL = intrinsics_from_fov(70.0, 48, 64)


@pytest.fixture(scope="module")
def room_renderer(room) -> ExactRenderer:
    return ExactRenderer(room)


@pytest.mark.parametrize("supersample", [1, 2])
def test_anchor_at_current_pose_reproduces_exact_render(room_renderer: ExactRenderer, supersample: int) -> None:
    camera = room_renderer.scene.cameras[0]
    renderer = DifferentiableRenderer(room_renderer, DiffRenderConfig(values="warp", supersample=supersample))
    out = renderer(torch.zeros(1, 6, dtype=torch.float64), camera.world_T_cam[None], K_SMALL, 48, 64)
    assert out.refreshed and float(out.coverage) > 0.95
    valid = out.depth > 0
    assert (out.rgb - out.exact.rgb).abs()[valid.expand_as(out.rgb)].max() <= 1e-5
    if supersample == 1:  # box-filtered depth differs from the centre ray only where a pixel spans a crease
        assert ((out.depth - out.exact.depth).abs() / out.exact.depth.clamp_min(1e-6))[valid].max() <= 1e-5


def test_values_exact_mode_keeps_exact_values(room_renderer: ExactRenderer) -> None:
    camera = room_renderer.scene.cameras[0]
    params = torch.tensor([[0.01, -0.02, 0.0, 0.05, 0.0, -0.03]], dtype=torch.float64, requires_grad=True)
    out = DifferentiableRenderer(room_renderer)(params, camera.world_T_cam[None], K_SMALL, 48, 64)
    assert torch.equal(out.rgb.detach(), out.exact.rgb) and torch.equal(out.depth.detach(), out.exact.depth)
    out.rgb.sum().backward()
    assert torch.isfinite(params.grad).all() and params.grad.abs().sum() > 0


def test_gradient_finite_at_zero_and_where_rays_miss(room_renderer: ExactRenderer) -> None:
    # a camera outside the room looking at it: most rays miss
    from kadv.geometry import look_at

    lo, hi = room_renderer.scene.bounds
    pose = look_at(torch.tensor(hi + [2.0, 1.0, 2.0]), torch.tensor((lo + hi) / 2)).double()[None]
    params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
    out = DifferentiableRenderer(room_renderer)(params, pose, K_SMALL, 48, 64)
    assert 0.05 < float(out.mask.float().mean()) < 0.95
    (out.rgb.sum() + out.depth.sum()).backward()
    assert torch.isfinite(params.grad).all() and params.grad.abs().sum() > 0


def test_bad_pose_params(room_renderer: ExactRenderer) -> None:
    camera = room_renderer.scene.cameras[0]
    with pytest.raises(ValueError, match="NaN"):
        DifferentiableRenderer(room_renderer)(
            torch.full((1, 6), float("nan")), camera.world_T_cam[None], K_SMALL, 48, 64
        )
    with pytest.raises(ValueError, match=r"\(B, 6\)"):
        DifferentiableRenderer(room_renderer)(torch.zeros(6), camera.world_T_cam[None], K_SMALL, 48, 64)
    with pytest.raises(ValueError, match=r"render.values"):
        DiffRenderConfig(values="magic")


@pytest.mark.real_scenes
def test_warp_mode_tracks_exact_render_along_a_trajectory(grey_white_room) -> None:
    renderer = ExactRenderer(grey_white_room)
    base = random_valid_poses(renderer, 1, np.random.default_rng(3), 70.0, min_clearance=0.5)
    K = intrinsics_from_fov(70.0, 60, 80)
    differentiable = DifferentiableRenderer(renderer, DiffRenderConfig(values="warp", refresh="every_k", every_k=5))
    refreshes = 0
    for step in range(20):
        phase = step / 19.0
        params = torch.tensor(
            [
                [
                    0.05 * np.sin(2 * phase),
                    0.15 * phase,
                    0.02 * phase,
                    0.2 * phase,
                    0.05 * np.sin(3 * phase),
                    0.15 * phase,
                ]
            ],
            dtype=torch.float64,
        )
        out = differentiable(params, base, K, 60, 80)
        refreshes += out.refreshed
        assert float(out.rgb_error) <= 0.02, (step, float(out.rgb_error))
        assert float(out.coverage) >= 0.9, (step, float(out.coverage))
    assert refreshes == 4  # steps 0, 5, 10, 15
