"""The attack objective: a loss between ground truth and prediction, minus the shortcut penalty.

The loss is the study's L_depth (``loss=perceptual|ssim``) or a loss on the aligned prediction
(``loss=absrel|delta1``); either way every view also gets L_depth, delta1 and AbsRel, so searches
with different losses are compared on the same measures.

Per sample (B,), so that the restarts of one init view go through renderer, model and loss as
one batch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from kadv.device import resolve_device
from kadv.losses import (
    SPACES,
    AlignedLoss,
    check_alignment,
    depth_metrics,
    kind_fit,
    minmax_normalize,
    ssim_loss,
    to_comparison_space,
)
from kadv.models import DepthModel
from kadv.penalties import PenaltyConfig, distance_to_surface, shortcut_penalty
from kadv.render import ExactRenderer

__all__ = ["Objective", "ObjectiveTerms"]


@dataclass
class ObjectiveTerms:
    """The objective's parts for B views; tensors (B,) unless said otherwise.

    Attributes:
        objective: loss - lambda * L_dist (to maximise), differentiable.
        loss: the attacked loss, differentiable (L_depth itself for the study's losses).
        l_depth: L_depth, the study's depth discrepancy (differentiable when it is the loss).
        l_dist: shortcut penalty, differentiable.
        distance: optical centre to nearest surface, metres.
        delta1, abs_rel: the prediction's accuracy after the objective's alignment (no gradient).
        prediction: (B, 1, H, W) the model's raw output (no gradient).
    """

    objective: torch.Tensor
    loss: torch.Tensor
    l_depth: torch.Tensor
    l_dist: torch.Tensor
    distance: torch.Tensor
    delta1: torch.Tensor
    abs_rel: torch.Tensor
    prediction: torch.Tensor


class Objective:
    """loss(D, phi(I)) - lambda * L_dist(c) for a differentiable render.

    For L_depth, ground truth and prediction go into one comparison space (a metric model's depth
    is converted), each is min-max normalised to [0, 1] over the valid pixels, and ``loss``
    compares them. An :class:`~kadv.losses.AlignedLoss` sees the raw prediction and aligns it to
    the ground truth in the comparison space; L_depth is then measured with SSIM. Gradients flow
    through both maps.

    Args:
        model: the depth model under attack.
        loss: per-sample discrepancy (B,) of two normalised maps (B, 1, H, W), or an aligned loss.
        renderer: the scene's exact renderer (for the distance to the nearest surface).
        penalty: d_th and lambda.
        space: "disparity" or "depth": where L_depth and the aligned losses compare the maps
            (``loss.space``); None: the space the model's kind is fitted in
            (:func:`kadv.losses.kind_fit`).
        alignment: how the prediction meets the ground truth before the aligned losses and the
            metrics score it (``loss.alignment``): ``scale_shift`` (least squares; the study's
            protocol), ``scale`` (least squares on scale alone) or ``none`` (the prediction as
            metric depth: a relative model is refused); None: the kind's own. L_depth compares
            min-max normalised maps whatever it is. The metrics are fitted in the kind's own space
            (:attr:`metric_space`).
        device: where the model and the loss run (see :mod:`kadv.device`); they are moved there.
            Inputs may live anywhere; the terms stay on that device (nothing is read back to the host).
    """

    def __init__(
        self,
        model: DepthModel,
        loss: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
        renderer: ExactRenderer,
        penalty: PenaltyConfig,
        space: str | None = None,
        device: str | torch.device = "cpu",
        alignment: str | None = None,
    ) -> None:
        if space not in (*SPACES, None):
            raise ValueError(f"loss.space must be 'disparity' or 'depth', got {space!r}")
        self.metric_space, self.alignment = kind_fit(model.output_kind, alignment=alignment)
        space = space or self.metric_space
        check_alignment(self.alignment, model.output_kind, f"model {getattr(model, 'name', type(model).__name__)}")
        self.device = resolve_device(device)
        self.model = model.to(self.device)
        self.loss = loss.to(self.device) if isinstance(loss, torch.nn.Module) else loss
        self.measure = ssim_loss if isinstance(loss, AlignedLoss) else self.loss
        self.renderer = renderer
        self.penalty = penalty
        self.space = space

    def l_depth(self, depth: torch.Tensor, prediction: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """L_depth (B,) between ground-truth z-depth and a prediction, both (B, 1, H, W)."""
        mask = mask & (depth > 0)
        gt = minmax_normalize(to_comparison_space(depth, "depth", self.space, mask), mask)
        pred = minmax_normalize(to_comparison_space(prediction, self.model.output_kind, self.space, mask), mask)
        return self.measure(gt.float(), pred.float()).double()

    def attacked_loss(self, depth: torch.Tensor, prediction: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """The loss the search climbs (B,) between ground-truth z-depth and a prediction (B, 1, H, W)."""
        if isinstance(self.loss, AlignedLoss):
            return self.loss(
                prediction.double(), depth.double(), mask, self.model.output_kind, self.space, self.alignment
            )
        return self.l_depth(depth, prediction, mask)

    def __call__(
        self,
        rgb: torch.Tensor,
        depth: torch.Tensor,
        mask: torch.Tensor,
        world_T_cam: torch.Tensor,
        K: torch.Tensor | None = None,
    ) -> ObjectiveTerms:
        return self.forward(rgb, depth, mask, world_T_cam, K)

    def forward(
        self,
        rgb: torch.Tensor,
        depth: torch.Tensor,
        mask: torch.Tensor,
        world_T_cam: torch.Tensor,
        K: torch.Tensor | None = None,
    ) -> ObjectiveTerms:
        """Evaluate B views.

        Args:
            rgb: (B, 3, H, W) rendered images in [0, 1].
            depth: (B, 1, H, W) ground-truth z-depth in metres (0 invalid).
            mask: (B, 1, H, W) bool, valid ground truth.
            world_T_cam: (B, 4, 4) the views' poses; the penalty's gradient flows to their centres.
            K: (3, 3) or (B, 3, 3) intrinsics, for models whose metric scale needs the focal length.
        """
        rgb, depth, mask = rgb.to(self.device), depth.to(self.device), mask.to(self.device)
        prediction = self.model(rgb.float(), K)
        loss = self.attacked_loss(depth, prediction, mask)
        if self.measure is self.loss:
            l_depth = loss
        else:
            with torch.no_grad():
                l_depth = self.l_depth(depth, prediction, mask)
        distance = distance_to_surface(self.renderer, world_T_cam[:, :3, 3].to(self.device))
        l_dist = shortcut_penalty(distance, self.penalty.d_th)
        with torch.no_grad():
            metrics = depth_metrics(
                prediction.double(),
                depth.double(),
                mask,
                self.model.output_kind,
                alignment=self.alignment,
                space=self.metric_space,
            )
        return ObjectiveTerms(
            objective=loss - self.penalty.weight * l_dist,
            loss=loss,
            l_depth=l_depth,
            l_dist=l_dist,
            distance=distance.detach(),
            delta1=metrics["delta1"],
            abs_rel=metrics["abs_rel"],
            prediction=prediction.detach(),
        )
