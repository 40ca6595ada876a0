from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.penalties import distance_to_surface, shortcut_penalty
from kadv.render import ExactRenderer
from kadv.scenes import box_room

SIZE = (5.0, 3.0, 4.0)


@pytest.fixture(scope="module")
def empty_room() -> ExactRenderer:
    return ExactRenderer(box_room(seed=2, size=SIZE, num_boxes=0))


def test_distance_and_penalty_match_the_formula_near_a_wall(empty_room: ExactRenderer) -> None:
    d_th = 0.1
    centre = torch.tensor([[0.05, 1.5, 2.0]], dtype=torch.float64, requires_grad=True)
    distance = distance_to_surface(empty_room, centre)
    assert float(distance.detach()) == pytest.approx(0.05, abs=1e-6)
    penalty = shortcut_penalty(distance, d_th)
    assert float(penalty.detach()) == pytest.approx(1 / 0.05 - 1 / d_th, rel=1e-4)
    penalty.sum().backward()
    # dL/dc = -1/d^2 * dd/dc, and dd/dc is the unit normal of the wall x = 0
    # Open3D works in float32: components that should be 0 come out near 1e-3 beside 400
    assert torch.allclose(
        centre.grad, torch.tensor([[-1 / 0.05**2, 0.0, 0.0]], dtype=torch.float64), rtol=1e-4, atol=1e-2
    )


def test_penalty_is_zero_with_zero_gradient_beyond_threshold(empty_room: ExactRenderer) -> None:
    centre = torch.tensor([[1.0, 1.5, 2.0]], dtype=torch.float64, requires_grad=True)
    penalty = shortcut_penalty(distance_to_surface(empty_room, centre), 0.1)
    penalty.sum().backward()
    assert float(penalty.detach()) == 0.0 and torch.equal(centre.grad, torch.zeros_like(centre))


def test_penalty_is_continuous_at_threshold() -> None:
    d = torch.tensor([0.1 - 1e-9, 0.1, 0.1 + 1e-9], dtype=torch.float64)
    assert torch.allclose(shortcut_penalty(d, 0.1), torch.zeros(3, dtype=torch.float64), atol=1e-6)


def test_distance_gradient_matches_finite_differences(empty_room: ExactRenderer) -> None:
    rng = np.random.default_rng(0)
    centres = torch.tensor(rng.uniform([0.3, 0.3, 0.3], [4.7, 2.7, 3.7], size=(16, 3)), requires_grad=True)
    distance = distance_to_surface(empty_room, centres)
    (grad,) = torch.autograd.grad(distance.sum(), centres)
    eps = 1e-3
    for axis in range(3):
        step = torch.zeros_like(centres)
        step[:, axis] = eps
        fd = (distance_to_surface(empty_room, centres + step) - distance_to_surface(empty_room, centres - step)) / (
            2 * eps
        )
        assert torch.allclose(grad[:, axis], fd.detach(), atol=1e-3)


def test_bad_centres_raise(empty_room: ExactRenderer) -> None:
    with pytest.raises(ValueError, match="NaN"):
        distance_to_surface(empty_room, torch.tensor([[float("nan"), 0.0, 0.0]]))
    with pytest.raises(ValueError, match=r"\(B, 3\)"):
        distance_to_surface(empty_room, torch.zeros(3))
    with pytest.raises(ValueError, match="d_th"):
        shortcut_penalty(torch.ones(1), 0.0)
