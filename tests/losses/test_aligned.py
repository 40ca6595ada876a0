"""The attack losses on the aligned prediction: AbsRel and the smooth delta1 share."""

from __future__ import annotations

import pytest
import torch

from kadv import DifferentiableRenderer, ExactRenderer, box_room
from kadv.attack import Objective, PenaltyConfig
from kadv.losses import AlignedLoss, absrel_loss, depth_loss, depth_metrics, soft_delta1_loss
from kadv.models import load_model

LOSSES = ("absrel", "delta1")


def _depth() -> tuple[torch.Tensor, torch.Tensor]:
    y, x = torch.meshgrid(
        torch.linspace(0, 1, 24, dtype=torch.float64), torch.linspace(0, 1, 32, dtype=torch.float64), indexing="ij"
    )
    depth = (1.0 + 3.0 * y + 0.5 * torch.sin(6 * x))[None, None]
    mask = torch.ones_like(depth, dtype=torch.bool)
    mask[..., :3, :3] = False
    return torch.where(mask, depth, torch.zeros_like(depth)), mask


@pytest.mark.parametrize("kind", LOSSES)
@pytest.mark.parametrize(
    "prediction_kind, space, perfect",
    [
        ("disparity", "disparity", lambda d: 3.0 / d.clamp_min(1e-3) + 7.0),
        ("depth", "depth", lambda d: 0.5 * d + 0.2),
        ("depth", "disparity", lambda d: 2.0 * d),
    ],
)
def test_zero_on_a_perfect_prediction_and_rising_with_the_error(kind, prediction_kind, space, perfect) -> None:
    loss = AlignedLoss(kind)
    depth, mask = _depth()
    assert float(loss(perfect(depth), depth, mask, prediction_kind, space)) == pytest.approx(0.0, abs=1e-9)
    wrong = [float(loss(perfect(depth * (1.0 + a * depth)), depth, mask, prediction_kind, space)) for a in (0.1, 0.4)]
    assert 0.0 < wrong[0] < wrong[1], wrong  # a depth-dependent distortion no alignment undoes


def test_absrel_is_the_reported_metric_and_smooth_delta1_tends_to_one_minus_delta1() -> None:
    depth, mask = _depth()
    prediction = 1.0 / (depth * (1.0 + depth.flip(-2))).clamp_min(1e-3)
    metrics = depth_metrics(prediction, depth, mask)
    assert float(absrel_loss(prediction, depth, mask)) == pytest.approx(float(metrics["abs_rel"]), rel=1e-12)
    sharp = float(soft_delta1_loss(prediction, depth, mask, temperature=1e-4))
    assert sharp == pytest.approx(1.0 - float(metrics["delta1"]), abs=0.01)
    assert 0.05 < sharp < 0.95  # some pixels right, some wrong: the comparison means something


def test_bad_kind_and_temperature_name_the_key() -> None:
    with pytest.raises(ValueError, match=r"loss.kind must be one of perceptual, ssim, absrel, delta1, got 'rmse'"):
        depth_loss("rmse")
    with pytest.raises(ValueError, match=r"loss.temperature must be positive, got 0.0"):
        depth_loss("delta1", temperature=0.0)


@pytest.fixture(scope="module")
def room() -> tuple[ExactRenderer, torch.Tensor, torch.Tensor]:
    renderer = ExactRenderer(box_room(seed=0))
    camera = renderer.scene.cameras[0]
    return renderer, camera.world_T_cam[None], camera.intrinsics(48, 64)


@pytest.mark.parametrize("kind", LOSSES)
def test_gradients_in_both_maps_match_finite_differences(kind) -> None:
    depth, mask = _depth()
    depth, mask = depth[..., ::3, ::4].contiguous(), mask[..., ::3, ::4].contiguous()  # 8 x 8
    prediction = 1.0 / (depth * (1.0 + 0.3 * depth.flip(-1))).clamp_min(1e-3)
    loss = AlignedLoss(kind, temperature=0.2)  # a wide step: the central differences stay in its smooth part
    inputs = (prediction.clone().requires_grad_(True), depth.clone().requires_grad_(True))
    assert torch.autograd.gradcheck(lambda p, d: loss(p, d, mask, "disparity", "disparity"), inputs, atol=1e-7)


@pytest.mark.parametrize("kind", LOSSES)
def test_a_pose_gradient_comes_back_through_renderer_model_and_loss(kind, room) -> None:
    """The renderer's pose gradients are checked against finite differences (tests/diagnostics) and
    the losses' map gradients above; here the chain reaches the pose with a finite, non-zero gradient."""
    renderer, base, K = room
    objective = Objective(load_model("kadv_tiny"), depth_loss(kind), renderer, PenaltyConfig())
    params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
    out = DifferentiableRenderer(renderer)(params, base, K, 48, 64)
    terms = objective(out.rgb, out.depth, out.mask, out.world_T_cam, K)
    assert torch.equal(terms.objective, terms.loss - objective.penalty.weight * terms.l_dist)
    terms.objective.sum().backward()
    assert torch.isfinite(params.grad).all() and params.grad[:, :3].norm() > 0 and params.grad[:, 3:].norm() > 0


@pytest.mark.parametrize("kind", LOSSES)
def test_runs_record_l_depth_delta1_and_absrel_whatever_the_loss(kind, room) -> None:
    renderer, base, K = room
    model = load_model("kadv_tiny")
    ssim = Objective(model, depth_loss("ssim"), renderer, PenaltyConfig())
    aligned = Objective(model, depth_loss(kind), renderer, PenaltyConfig())
    out = renderer.render(base, K, 48, 64)
    a, b = (o(out.rgb, out.depth, out.mask, base, K) for o in (ssim, aligned))
    assert torch.allclose(a.l_depth, b.l_depth, atol=1e-6)  # L_depth is measured with SSIM either way
    assert torch.equal(a.delta1, b.delta1) and torch.equal(a.abs_rel, b.abs_rel)
    if kind == "absrel":
        assert torch.allclose(b.loss, b.abs_rel, rtol=1e-5)
