from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.geometry import intrinsics_from_fov
from kadv.penalties import random_valid_poses
from kadv.render import DifferentiableRenderer, DiffRenderConfig, ExactRenderer, dibr
from kadv.render import differentiable as differentiable_module

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
    with pytest.raises(ValueError, match=r"render\.differentiable\.values"):
        DiffRenderConfig(values="magic")
    with pytest.raises(ValueError, match=r"render\.differentiable\.layers.*got 0,"):
        DiffRenderConfig(layers=0)
    with pytest.raises(ValueError, match=r"render\.differentiable\.anchor_reach_deg.*got 0\.0 and 0\.1"):
        DiffRenderConfig(anchor_reach_deg=0.0)


def _trajectory(step: int, steps: int) -> torch.Tensor:
    phase = step / (steps - 1)
    return torch.tensor(
        [[0.05 * np.sin(2 * phase), 0.15 * phase, 0.02 * phase, 0.2 * phase, 0.05 * np.sin(3 * phase), 0.15 * phase]],
        dtype=torch.float64,
    )


@pytest.mark.real_scenes
def test_warp_mode_tracks_exact_render_along_a_trajectory(grey_white_room) -> None:
    renderer = ExactRenderer(grey_white_room)
    base = random_valid_poses(renderer, 1, np.random.default_rng(3), 70.0, min_clearance=0.5)
    K = intrinsics_from_fov(70.0, 60, 80)
    differentiable = DifferentiableRenderer(renderer, DiffRenderConfig(values="warp", refresh="every_k", every_k=5))
    refreshes = 0
    for step in range(20):
        out = differentiable(_trajectory(step, 20), base, K, 60, 80)
        refreshes += out.refreshed
        assert out.warped != out.refreshed
        exact = renderer.render(out.world_T_cam.detach(), K, 60, 80, supersample=2)
        assert float((out.rgb.detach() - exact.rgb).abs().mean()) <= 0.02, step
        # the cast's depth (the ring's interior), the warp's gradient
        torch.testing.assert_close(out.depth.detach(), exact.depth, rtol=1e-6, atol=0)
        assert float(out.coverage) >= 0.9, (step, float(out.coverage))
    assert refreshes == 4  # steps 0, 5, 10, 15


def test_between_refreshes_the_warp_renders_no_shaded_image(room_renderer: ExactRenderer, monkeypatch) -> None:
    """values=warp: a step between refreshes casts its view without shading, shades only the
    pixels no anchor layer holds and follows the occlusion edges found last instead of searching
    them; the shaded renders and the edge searches are the refreshes' (one anchor and one frame
    each) and the view a search validates."""
    renderer = ExactRenderer(room_renderer.scene)
    calls = {"shaded": 0, "bare": 0, "anchors": 0, "rays": 0, "interpolated": 0, "in_bare": False}
    calls |= {"edge searches": 0, "edges followed": 0}
    render, shade = renderer.render, renderer.cast_and_shade

    def counted_render(*args, colour: bool = True, **kwargs):
        calls["shaded" if colour else "bare"] += 1
        calls["in_bare"] = not colour
        try:
            return render(*args, colour=colour, **kwargs)
        finally:
            calls["in_bare"] = False

    def counted_shade(origins, directions, pixel_angle, colour, geometry, normals=True):
        calls["rays"] += len(origins) if colour else 0
        calls["interpolated"] += len(origins) if normals and calls["in_bare"] else 0
        return shade(origins, directions, pixel_angle, colour, geometry, normals)

    monkeypatch.setattr(renderer, "render", counted_render)
    monkeypatch.setattr(renderer, "cast_and_shade", counted_shade)
    monkeypatch.setattr(differentiable_module, "render_anchor", _counting(differentiable_module.render_anchor, calls))
    search, follow = differentiable_module.find_edge_pairs, differentiable_module.track_edge_pairs
    monkeypatch.setattr(differentiable_module, "find_edge_pairs", _counting(search, calls, "edge searches"))
    monkeypatch.setattr(differentiable_module, "track_edge_pairs", _counting(follow, calls, "edges followed"))
    camera = renderer.scene.cameras[0]
    config = DiffRenderConfig(values="warp", refresh="every_k", every_k=4, layers=2)
    differentiable = DifferentiableRenderer(renderer, config)
    warped_rays = 0
    for step in range(10):
        if step == 9:
            differentiable.validate_next()
        params = (0.3 * _trajectory(step, 10)).requires_grad_(True)
        before = calls["rays"]
        out = differentiable(params, camera.world_T_cam[None], K_SMALL, 48, 64)
        (out.rgb.sum() + out.depth.sum()).backward()
        assert torch.isfinite(params.grad).all() and params.grad.abs().sum() > 0
        if out.warped:
            warped_rays += calls["rays"] - before
    # refreshes at steps 0, 4 and 8 (an anchor and a frame each), and step 9 validated exactly
    assert calls["anchors"] == 3 and calls["shaded"] == 4 and calls["bare"] == 6
    assert calls["interpolated"] == 0  # the bare casts interpolate no shading normals
    # the exact frames search their occlusion edges; the warped steps follow the last search's
    assert calls["edge searches"] == 4 and calls["edges followed"] == 6
    # the warped steps (1-3 and 5-7) shaded only their holes: far fewer rays than their frames'
    assert 0 < warped_rays < 0.15 * 6 * config.supersample**2 * (48 + 2) * (64 + 2)


def test_the_warp_preset_reads_the_boxed_anchor_at_its_refreshes_too(room_renderer: ExactRenderer, monkeypatch) -> None:
    """values=warp never runs the closed-form at-anchor warp (the default step's): a refresh's
    gradient comes from the boxed anchor, as the steps between refreshes do, and it is nonzero."""

    def closed_form(*args, **kwargs):
        raise AssertionError("the closed-form warp ran under values=warp")

    monkeypatch.setattr(dibr, "_anchor_layer_pixels", closed_form)
    camera = room_renderer.scene.cameras[0]
    differentiable = DifferentiableRenderer(
        room_renderer, DiffRenderConfig(values="warp", refresh="every_k", every_k=2)
    )
    for step in range(4):
        params = (0.3 * _trajectory(step, 4)).requires_grad_(True)
        out = differentiable(params, camera.world_T_cam[None], K_SMALL, 48, 64)
        (out.rgb.sum() + out.depth.sum()).backward()
        assert out.refreshed == (step % 2 == 0) and float(params.grad.abs().sum()) > 0


@pytest.mark.parametrize(
    ("move", "refreshed"),
    [
        ([0.0, 0.06, 0.0, 0.0, 0.0, 0.0], False),  # 3.4 degrees, within the 4 degrees
        ([0.0, 0.08, 0.0, 0.0, 0.0, 0.0], True),  # 4.6 degrees
        ([0.0, 0.0, 0.0, 0.06, 0.0, 0.06], False),  # 8.5 cm, within the 10 cm
        ([0.0, 0.0, 0.0, 0.08, 0.0, 0.08], True),  # 11.3 cm
    ],
)
def test_a_view_beyond_the_anchor_s_reach_renders_a_new_anchor_whatever_the_step_count(
    room_renderer: ExactRenderer, move: list[float], refreshed: bool
) -> None:
    """The warp's gradients hold out to the anchor's reach (benchmarks/gradcheck.py checks them
    there): a view beyond it, by its rotation or its centre, renders a new anchor first, long
    before ``every_k`` steps, and one within it is warped."""
    camera = room_renderer.scene.cameras[0]
    config = DiffRenderConfig(values="warp", refresh="every_k", every_k=100, anchor_reach_deg=4.0, anchor_reach_m=0.1)
    differentiable = DifferentiableRenderer(room_renderer, config)
    assert differentiable(torch.zeros(1, 6, dtype=torch.float64), camera.world_T_cam[None], K_SMALL, 48, 64).refreshed
    out = differentiable(torch.tensor([move], dtype=torch.float64), camera.world_T_cam[None], K_SMALL, 48, 64)
    assert out.refreshed == refreshed and out.warped != refreshed
    # warped: the view lies its move from the anchor; refreshed: on the new anchor
    turned, moved = differentiable.anchor_distance(out.world_T_cam)
    expected = (0.0, 0.0) if refreshed else (float(torch.tensor(move[:3]).norm()), float(torch.tensor(move[3:]).norm()))
    assert (float(turned), float(moved)) == pytest.approx(expected, abs=1e-9)


def _counting(fn, calls: dict, key: str = "anchors"):
    def counted(*args, **kwargs):
        calls[key] += 1
        return fn(*args, **kwargs)

    return counted


@pytest.mark.parametrize(("min_coverage", "warped"), [(0.5, True), (1.0, False)])
def test_on_drift_the_warp_refreshes_when_its_coverage_falls(room_renderer, min_coverage, warped) -> None:
    """values=warp, refresh=on_drift: a moved view whose warp covers less than ``min_coverage`` of
    its pixels is rendered again exactly, with a new anchor; one that covers enough is warped."""
    camera = room_renderer.scene.cameras[0]
    config = DiffRenderConfig(values="warp", refresh="on_drift", min_coverage=min_coverage, layers=2)
    differentiable = DifferentiableRenderer(room_renderer, config)
    differentiable(torch.zeros(1, 6, dtype=torch.float64), camera.world_T_cam[None], K_SMALL, 48, 64)
    out = differentiable(0.3 * _trajectory(3, 10), camera.world_T_cam[None], K_SMALL, 48, 64)
    assert out.warped == warped and out.refreshed == (not warped)
    assert 0.8 < float(out.coverage) < 1.0
