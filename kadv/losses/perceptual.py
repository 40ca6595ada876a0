"""L_depth: perceptual distance between normalised depth maps, and a weight-free SSIM variant."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import torch
from kornia.enhance import normalize
from kornia.losses import ssim_loss as kornia_ssim_loss
from torch import nn

from kadv.losses.aligned import ALIGNED_LOSSES, DELTA1_TEMPERATURE, AlignedLoss
from kadv.losses.vgg import VGG16_TAPS, load_vgg16_state_dict, vgg16_features

__all__ = ["IMAGENET_MEAN", "IMAGENET_STD", "PerceptualLoss", "depth_loss", "ssim_loss"]

IMAGENET_MEAN = torch.tensor([0.485, 0.456, 0.406])
IMAGENET_STD = torch.tensor([0.229, 0.224, 0.225])


class PerceptualLoss(nn.Module):
    """sum_j mean |psi_j(a) - psi_j(b)| over feature taps j (each term averaged over C_j H_j W_j).

    Inputs are depth maps normalised to [0, 1] (B, 1, H, W); they are repeated to 3 channels and
    ImageNet-normalised, as the study fed them to VGG-16. Parameters are frozen.

    Args:
        network: a sequential feature extractor.
        taps: indices of the modules whose outputs are compared.
    """

    def __init__(self, network: nn.Sequential, taps: Sequence[int]) -> None:
        super().__init__()
        if not taps or max(taps) >= len(network):
            raise ValueError(f"taps {list(taps)} do not fit a network of {len(network)} modules")
        self.network = network[: max(taps) + 1].eval()
        self.taps = tuple(taps)
        for parameter in self.network.parameters():
            parameter.requires_grad_(False)

    @classmethod
    def vgg16(cls, weights: str | Path | None = None) -> PerceptualLoss:
        """The study's loss: VGG-16 (ImageNet) at relu1_2, relu2_2, relu3_3, relu4_3."""
        network = vgg16_features()
        network.load_state_dict(load_vgg16_state_dict(weights))
        return cls(network, VGG16_TAPS)

    def features(self, depth: torch.Tensor) -> list[torch.Tensor]:
        x = normalize(depth.expand(-1, 3, -1, -1), IMAGENET_MEAN.to(depth), IMAGENET_STD.to(depth))
        taps = []
        for index, module in enumerate(self.network):
            x = module(x)
            if index in self.taps:
                taps.append(x)
        return taps

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """Per-sample loss (B,) between normalised maps a, b (B, 1, H, W)."""
        return sum((fa - fb).abs().mean(dim=(1, 2, 3)) for fa, fb in zip(self.features(a), self.features(b)))


def ssim_loss(a: torch.Tensor, b: torch.Tensor, window_size: int = 11) -> torch.Tensor:
    """Per-sample structural dissimilarity (1 - SSIM) / 2 (B,) of normalised maps (B, 1, H, W).

    Examples:
        >>> ramp = torch.linspace(0.0, 1.0, 256).reshape(1, 1, 16, 16)
        >>> ssim_loss(ramp, ramp).tolist()  # (1 - SSIM) / 2 per sample
        [0.0]
        >>> 0.0 < ssim_loss(ramp, ramp.flip(-1)).item() <= 1.0
        True
    """
    per_pixel = kornia_ssim_loss(a, b, window_size=window_size, max_val=1.0, reduction="none")
    return per_pixel.mean(dim=(1, 2, 3))


def depth_loss(
    kind: str, vgg_weights: str | Path | None = None, window_size: int = 11, temperature: float = DELTA1_TEMPERATURE
) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor] | AlignedLoss:
    """The attack loss a ``loss/`` config names: the study's L_depth on normalised maps, "perceptual"
    (VGG-16) or "ssim", or an :class:`AlignedLoss` on the aligned prediction, "absrel" or "delta1".

    Raises:
        ValueError: an unknown kind or a bad window size.

    Examples:
        >>> loss = depth_loss("ssim")
        >>> ramp = torch.linspace(0.0, 1.0, 64).reshape(1, 1, 8, 8)
        >>> loss(ramp, ramp).item() < 1e-6, loss(ramp, 1.0 - ramp).item() > 0.1
        (True, True)
    """
    if kind == "perceptual":
        return PerceptualLoss.vgg16(vgg_weights)
    if kind == "ssim":
        if window_size < 3 or window_size % 2 == 0:
            raise ValueError(f"loss.window_size must be an odd integer >= 3, got {window_size}")
        return partial(ssim_loss, window_size=window_size)
    if kind in ALIGNED_LOSSES:
        return AlignedLoss(kind, temperature)
    raise ValueError(f"loss.kind must be one of perceptual, ssim, {', '.join(ALIGNED_LOSSES)}, got {kind!r}")
