from __future__ import annotations

import pytest
import torch

from kadv.attack import Objective, PenaltyConfig
from kadv.losses import depth_loss


class _OutputKind:
    """Stands in for a model where only its output kind matters (l_depth of given maps)."""

    def __init__(self, kind: str) -> None:
        self.output_kind = kind

    def to(self, device: torch.device) -> _OutputKind:
        return self


def _objective(tiny_objective, kind: str) -> Objective:
    return Objective(_OutputKind(kind), depth_loss("ssim"), tiny_objective.renderer, PenaltyConfig())


def _depth() -> tuple[torch.Tensor, torch.Tensor]:
    y, x = torch.meshgrid(torch.linspace(0, 1, 32), torch.linspace(0, 1, 48), indexing="ij")
    depth = (1.0 + 2.0 * y + 0.5 * torch.sin(6 * x)).double()[None, None]
    mask = torch.ones_like(depth, dtype=torch.bool)
    mask[..., :4, :4] = False
    return torch.where(mask, depth, torch.zeros_like(depth)), mask


@pytest.mark.parametrize(
    "kind, perfect", [("disparity", lambda d: 3.0 / d.clamp_min(1e-3) + 7.0), ("depth", lambda d: 0.5 * d)]
)
def test_l_depth_is_zero_for_a_prediction_equal_up_to_scale_and_positive_otherwise(
    tiny_objective, kind, perfect
) -> None:
    objective = _objective(tiny_objective, kind)
    depth, mask = _depth()
    assert float(objective.l_depth(depth, perfect(depth), mask)) == pytest.approx(0.0, abs=1e-6)
    assert float(objective.l_depth(depth, perfect(depth.flip(-1)), mask)) > 0.05


def test_l_depth_has_gradients_in_both_maps(tiny_objective) -> None:
    objective = _objective(tiny_objective, "disparity")
    depth, mask = _depth()
    depth = depth.clone().requires_grad_(True)
    prediction = (1.0 / depth.detach().clamp_min(1e-3)).flip(-2).clone().requires_grad_(True)
    objective.l_depth(depth, prediction, mask).sum().backward()
    for tensor in (depth, prediction):
        assert torch.isfinite(tensor.grad).all() and tensor.grad[mask].abs().sum() > 0


def test_objective_subtracts_the_weighted_shortcut_penalty(tiny_objective) -> None:
    renderer = tiny_objective.renderer
    objective = Objective(tiny_objective.model, depth_loss("ssim"), renderer, PenaltyConfig(d_th=0.5, weight=2.0))
    camera = renderer.scene.cameras[0]
    near_wall = camera.world_T_cam.clone()
    near_wall[:3, 3] = torch.tensor([1.5, 1.5, 0.3], dtype=torch.float64)  # 0.3 m from the wall z = 0
    poses = torch.stack([camera.world_T_cam, near_wall])
    out = renderer.render(poses, camera.intrinsics(24, 32), 24, 32)
    terms = objective(out.rgb, out.depth, out.mask, poses)
    assert terms.objective.shape == terms.l_depth.shape == (2,)
    assert float(terms.l_dist[1]) == pytest.approx(1 / 0.3 - 1 / 0.5, rel=1e-3)
    assert torch.allclose(terms.objective, terms.l_depth - 2.0 * terms.l_dist)
    assert ((terms.delta1 >= 0) & (terms.delta1 <= 1)).all()
