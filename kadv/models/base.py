"""The depth-model interface every adapter implements."""

from __future__ import annotations

import torch
from torch import nn

from kadv.checks import check_shape
from kadv.losses.align import check_kind
from kadv.models.preprocess import Preprocess

__all__ = ["DepthModel"]


class DepthModel(nn.Module):
    """rgb (B, 3, H, W) in [0, 1] -> (B, 1, H, W) prediction at the input size, differentiable in rgb.

    Subclasses implement :meth:`predict` on the network input; the base class makes that input
    and brings the output back with its :class:`Preprocess` (None passes the image through as it
    is). Parameters are frozen and the module stays in eval mode.

    Attributes:
        output_kind: what the prediction holds (:data:`kadv.losses.KINDS`): "disparity" (relative
            inverse depth, affine-invariant), "depth" (metric), "affine_depth" (depth up to scale
            and shift) or "scale_depth" (depth up to scale).
        name: a label for reports.
    """

    output_kind: str = "disparity"

    def __init__(self, preprocess: Preprocess | None, output_kind: str, name: str) -> None:
        super().__init__()
        self.preprocess = preprocess
        self.output_kind = check_kind(output_kind)
        self.name = name

    def freeze(self) -> DepthModel:
        for parameter in self.parameters():
            parameter.requires_grad_(False)
        return self.eval()

    def train(self, mode: bool = True) -> DepthModel:
        """Stays in eval mode: attacks need deterministic, batch-independent predictions."""
        return super().train(False)

    def predict(self, pixel_values: torch.Tensor) -> torch.Tensor:
        """Network output (B, h, w) or (B, 1, h, w) for normalised input (B, 3, h, w)."""
        raise NotImplementedError

    def forward(self, rgb: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        """Prediction (B, 1, H, W) for images (B, 3, H, W) in [0, 1]; it runs where the model's
        parameters are and comes back on ``rgb``'s device.

        Args:
            rgb: (B, 3, H, W) images in [0, 1].
            K: (3, 3) or (B, 3, 3) pinhole intrinsics of the images, for models whose metric scale
                depends on the focal length (DepthPro); the others ignore it.
        """
        check_shape(rgb, "B 3 H W", "rgb")
        parameter = next(self.parameters(), None)
        x = rgb if parameter is None else rgb.to(parameter.device)
        if self.preprocess is None:
            return self._as_map(self.predict(x)).to(rgb.device)
        pixel_values, layout = self.preprocess.to_network(x)
        return self.preprocess.from_network(self._as_map(self.predict(pixel_values)), layout).to(rgb.device)

    @staticmethod
    def _as_map(out: torch.Tensor) -> torch.Tensor:
        """(B, 1, h, w) from a network's (B, h, w) or (B, 1, h, w)."""
        return out.unsqueeze(1) if out.ndim == 3 else out
