"""The depth-model interface every adapter implements."""
from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from kornia.enhance import normalize
from kornia.geometry.transform import resize
from torch import nn

from kadv.checks import check_shape

__all__ = ["DepthModel", "Preprocess", "constrain_to_multiple", "resized_shape"]


def constrain_to_multiple(value: float, multiple: int) -> int:
    """Round to the nearest multiple (never to 0), as Hugging Face's DPT processor does."""
    rounded = round(value / multiple) * multiple
    return int(rounded if rounded >= multiple else math.ceil(value / multiple) * multiple)


def resized_shape(height: int, width: int, size: tuple[int, int], keep_aspect_ratio: bool, multiple: int) -> tuple[int, int]:
    """The network input size for an image, following the DPT / Depth Anything processors.

    With ``keep_aspect_ratio`` the axis that needs the smaller change sets the scale of both.
    """
    scale_h, scale_w = size[0] / height, size[1] / width
    if keep_aspect_ratio:
        if abs(1 - scale_w) < abs(1 - scale_h):
            scale_h = scale_w
        else:
            scale_w = scale_h
    return constrain_to_multiple(scale_h * height, multiple), constrain_to_multiple(scale_w * width, multiple)


@dataclass(frozen=True)
class Preprocess:
    """How a model wants its input: target size, aspect handling, multiple, normalisation."""

    size: tuple[int, int]
    keep_aspect_ratio: bool = False
    multiple: int = 1
    mean: tuple[float, float, float] = (0.485, 0.456, 0.406)
    std: tuple[float, float, float] = (0.229, 0.224, 0.225)
    interpolation: str = "bicubic"

    def normalize(self, rgb: torch.Tensor) -> torch.Tensor:
        """(rgb - mean) / std per channel for rgb (B, 3, h, w) in [0, 1]."""
        as_tensor = lambda values: torch.tensor(values, dtype=rgb.dtype, device=rgb.device)  # noqa: E731
        return normalize(rgb, as_tensor(self.mean), as_tensor(self.std))


class DepthModel(nn.Module):
    """rgb (B, 3, H, W) in [0, 1] -> (B, 1, H, W) prediction at the input size, differentiable in rgb.

    Subclasses implement :meth:`predict` on the preprocessed tensor; the base class resizes with
    kornia, normalises, and resizes the output back (a ``preprocess`` of None passes the image
    through as it is). Parameters are frozen and the module stays in
    eval mode.

    Attributes:
        output_kind: "disparity" (relative inverse depth, affine-invariant) or "depth" (metric).
        name: a label for reports.
    """

    output_kind: str = "disparity"

    def __init__(self, preprocess: Preprocess | None, output_kind: str, name: str) -> None:
        super().__init__()
        if output_kind not in ("disparity", "depth"):
            raise ValueError(f"output_kind must be 'disparity' or 'depth', got {output_kind!r}")
        self.preprocess = preprocess
        self.output_kind = output_kind
        self.name = name

    def freeze(self) -> DepthModel:
        for parameter in self.parameters():
            parameter.requires_grad_(False)
        return self.eval()

    def train(self, mode: bool = True) -> DepthModel:  # noqa: FBT001, FBT002
        """Stays in eval mode: attacks need deterministic, batch-independent predictions."""
        return super().train(False)

    def predict(self, pixel_values: torch.Tensor) -> torch.Tensor:
        """Network output (B, h, w) or (B, 1, h, w) for normalised input (B, 3, h, w)."""
        raise NotImplementedError

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        """Prediction (B, 1, H, W) for images (B, 3, H, W) in [0, 1]; it runs where the model's
        parameters are and comes back on ``rgb``'s device."""
        check_shape(rgb, "B 3 H W", "rgb")
        height, width = rgb.shape[-2:]
        p = self.preprocess
        parameter = next(self.parameters(), None)
        x = rgb if parameter is None else rgb.to(parameter.device)
        if p is not None:
            shape = resized_shape(height, width, p.size, p.keep_aspect_ratio, p.multiple)
            x = resize(x, shape, interpolation=p.interpolation, align_corners=False) if shape != (height, width) else x
            x = p.normalize(x)
        out = self.predict(x)
        if out.ndim == 3:
            out = out.unsqueeze(1)
        if p is not None:
            out = resize(out, (height, width), interpolation="bilinear", align_corners=False)
        return out.to(rgb.device)
