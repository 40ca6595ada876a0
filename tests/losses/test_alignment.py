"""``loss.alignment``: how a prediction meets the ground truth before delta1, AbsRel and the aligned
losses score it (analytic cases on a ramp of depths)."""

from __future__ import annotations

import pytest
import torch

from kadv import ExactRenderer, box_room
from kadv.attack import Objective, PenaltyConfig
from kadv.losses import (
    ALIGNMENTS,
    KINDS,
    absrel_loss,
    align_scale,
    aligned_depth,
    check_kind,
    depth_metrics,
    kind_fit,
    soft_delta1_loss,
)
from kadv.models import load_model

DEPTH = 1.0 + torch.arange(64.0, dtype=torch.float64).reshape(1, 1, 8, 8) / 16  # 1 to 4.9 m
MASK = torch.ones_like(DEPTH, dtype=torch.bool)


@pytest.mark.parametrize("alignment", ALIGNMENTS)
def test_a_perfect_metric_prediction_scores_delta1_1_under_every_alignment(alignment) -> None:
    metrics = depth_metrics(DEPTH.clone(), DEPTH, MASK, "depth", alignment=alignment)
    assert metrics["delta1"].item() == 1.0 and metrics["abs_rel"].item() < 1e-9
    assert absrel_loss(DEPTH.clone(), DEPTH, MASK, "depth", alignment=alignment).item() < 1e-9


@pytest.mark.parametrize("space", ["disparity", "depth"])
def test_a_prediction_twice_too_far_is_right_up_to_scale_and_wrong_in_metres(space) -> None:
    twice = 2.0 * DEPTH
    for alignment, delta1, absrel in (("scale_shift", 1.0, 0.0), ("scale", 1.0, 0.0), ("none", 0.0, 1.0)):
        metrics = depth_metrics(twice, DEPTH, MASK, "depth", alignment=alignment)
        assert metrics["delta1"].item() == delta1, alignment
        assert absrel_loss(twice, DEPTH, MASK, "depth", space, alignment=alignment).item() == pytest.approx(absrel)
        smooth = soft_delta1_loss(twice, DEPTH, MASK, "depth", space, alignment=alignment).item()
        assert smooth == pytest.approx(1.0 - delta1, abs=1e-3), alignment  # log 2 is 9 temperatures past log 1.25


def test_scale_alone_keeps_a_shift_that_scale_and_shift_removes() -> None:
    shifted = DEPTH + 2.0  # metres: a shift no scale removes
    assert depth_metrics(shifted, DEPTH, MASK, "depth", alignment="scale_shift")["delta1"].item() == 1.0
    assert depth_metrics(shifted, DEPTH, MASK, "depth", alignment="scale")["delta1"].item() < 1.0
    assert torch.allclose(align_scale(3.0 * DEPTH, DEPTH, MASK), DEPTH)
    # in disparity space the scale of a metric prediction is found as well
    assert torch.allclose(aligned_depth(0.5 * DEPTH, DEPTH, MASK, "depth", "disparity", "scale"), DEPTH)


def test_a_relative_prediction_cannot_be_scored_as_metres_and_an_unknown_alignment_is_named() -> None:
    with pytest.raises(ValueError, match=r"^loss.alignment=none scores the prediction as metric depth, but the model"):
        depth_metrics(DEPTH, DEPTH, MASK, "disparity", alignment="none")
    renderer = ExactRenderer(box_room(seed=0))
    with pytest.raises(ValueError, match=r"but model kadv_tiny outputs relative disparity: use scale_shift or scale$"):
        Objective(load_model("kadv_tiny"), lambda a, b: a.mean(), renderer, PenaltyConfig(), alignment="none")
    with pytest.raises(ValueError, match=r"^loss.alignment must be one of scale_shift, scale, none, got 'affine'$"):
        depth_metrics(DEPTH, DEPTH, MASK, "depth", alignment="affine")


# a depth range wide enough (0.5 m to 8 m) that an affine map of depth is not one of disparity
WIDE = torch.linspace(0.5, 8.0, 64, dtype=torch.float64).reshape(1, 1, 8, 8)
EVERYWHERE = torch.ones_like(WIDE, dtype=torch.bool)


def _delta1(prediction: torch.Tensor, kind: str) -> float:
    return float(depth_metrics(prediction, WIDE, EVERYWHERE, kind)["delta1"])


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_perfect_prediction_scores_delta1_1_under_every_kind(kind: str) -> None:
    perfect = 1.0 / WIDE if kind == "disparity" else WIDE
    assert _delta1(perfect, kind) == 1.0


def test_an_affine_map_of_depth_is_right_as_affine_depth_and_wrong_as_disparity() -> None:
    affine = 0.2 * WIDE - 0.05  # Marigold's kind: depth up to scale and shift
    assert _delta1(affine, "affine_depth") == 1.0
    assert _delta1(affine, "disparity") < 0.9


def test_an_affine_map_of_disparity_is_right_as_disparity_and_wrong_as_affine_depth() -> None:
    affine = 3.0 / WIDE + 0.4
    assert _delta1(affine, "disparity") == 1.0
    assert _delta1(affine, "affine_depth") < 0.9


@pytest.mark.parametrize("kind", ["disparity", "affine_depth", "scale_depth"])
def test_a_scale_of_the_right_map_is_right_under_every_relative_kind(kind: str) -> None:
    right = 1.0 / WIDE if kind == "disparity" else WIDE
    assert _delta1(7.5 * right, kind) == 1.0


def test_each_kind_is_fitted_with_its_own_ambiguity_in_its_own_space_by_default() -> None:
    assert {kind: kind_fit(kind) for kind in KINDS} == {
        "disparity": ("disparity", "scale_shift"),
        "depth": ("disparity", "scale_shift"),
        "affine_depth": ("depth", "scale_shift"),
        "scale_depth": ("depth", "scale"),
    }
    # scale alone in depth space: a shifted depth is not a scale-invariant one
    assert _delta1(WIDE + 2.0, "scale_depth") < 0.9
    with pytest.raises(ValueError, match="outputs affine-invariant depth: use scale_shift or scale"):
        depth_metrics(WIDE, WIDE, EVERYWHERE, "affine_depth", alignment="none")
    with pytest.raises(ValueError, match="output_kind must be one of disparity, depth, affine_depth, scale_depth"):
        check_kind("inverse_depth")


def test_an_objective_fits_its_metrics_in_the_model_kind_s_space() -> None:
    from kadv.models import wrap_model

    class Affine(torch.nn.Module):
        def forward(self, rgb: torch.Tensor) -> torch.Tensor:
            return rgb.mean(dim=1, keepdim=True) + 1.0

    renderer = ExactRenderer(box_room(seed=0))
    objective = Objective(
        wrap_model(Affine(), "affine_depth"), lambda a, b: (a - b).abs().mean((1, 2, 3)), renderer, PenaltyConfig()
    )
    assert (objective.space, objective.metric_space, objective.alignment) == ("depth", "depth", "scale_shift")
    relative = Objective(load_model("kadv_tiny"), lambda a, b: (a - b).abs().mean((1, 2, 3)), renderer, PenaltyConfig())
    assert (relative.space, relative.metric_space, relative.alignment) == ("disparity", "disparity", "scale_shift")
