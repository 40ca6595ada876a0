"""``loss.alignment``: how a prediction meets the ground truth before delta1, AbsRel and the aligned
losses score it (analytic cases on a ramp of depths)."""

from __future__ import annotations

import pytest
import torch

from kadv import ExactRenderer, box_room
from kadv.attack import Objective, PenaltyConfig
from kadv.losses import ALIGNMENTS, absrel_loss, align_scale, aligned_depth, depth_metrics, soft_delta1_loss
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
