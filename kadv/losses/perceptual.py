"""L_depth: perceptual distance between normalised depth maps, and a weight-free SSIM variant."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import torch
from kornia.enhance import normalize
from kornia.filters import filter2d_separable, get_gaussian_kernel1d
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
        mean, std = (v.to(depth, non_blocking=True) for v in (IMAGENET_MEAN, IMAGENET_STD))
        x = normalize(depth.expand(-1, 3, -1, -1), mean, std)
        taps = []
        for index, module in enumerate(self.network):
            x = module(x)
            if index in self.taps:
                taps.append(x)
        return taps

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """Per-sample loss (B,) between normalised maps a, b (B, 1, H, W)."""
        return sum((fa - fb).abs().mean(dim=(1, 2, 3)) for fa, fb in zip(self.features(a), self.features(b)))


@functools.lru_cache(maxsize=16)
def _gaussian_window(window_size: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """SSIM's Gaussian window (1, window_size), sigma 1.5, made once per device: kornia builds it from a
    host number at every call, an upload that waits for the device's queue."""
    return get_gaussian_kernel1d(window_size, 1.5, device=device, dtype=dtype)


# SSIM's stabilising constants for a dynamic range of 1 (Wang et al. 2004), and kornia's eps
_C1, _C2, _EPS = 0.01**2, 0.03**2, 1e-12


def ssim_loss(a: torch.Tensor, b: torch.Tensor, window_size: int = 11) -> torch.Tensor:
    """Per-sample structural dissimilarity (1 - SSIM) / 2 (B,) of normalised maps (B, 1, H, W).

    kornia's ``ssim_loss`` (same padding, max_val 1), value for value, with its Gaussian window
    made once per device.

    Examples:
        >>> ramp = torch.linspace(0.0, 1.0, 256).reshape(1, 1, 16, 16)
        >>> ssim_loss(ramp, ramp).tolist()  # (1 - SSIM) / 2 per sample
        [0.0]
        >>> 0.0 < ssim_loss(ramp, ramp.flip(-1)).item() <= 1.0
        True
    """
    kernel = _gaussian_window(window_size, a.device, torch.promote_types(a.dtype, b.dtype))
    a, b = a.to(kernel.dtype), b.to(kernel.dtype)

    def blur(image: torch.Tensor) -> torch.Tensor:
        return filter2d_separable(image, kernel, kernel)

    mu_a, mu_b = blur(a), blur(b)
    mu_a_sq, mu_b_sq, mu_ab = mu_a**2, mu_b**2, mu_a * mu_b
    sigma_a_sq = blur(a**2) - mu_a_sq
    sigma_b_sq = blur(b**2) - mu_b_sq
    sigma_ab = blur(a * b) - mu_ab
    ssim = ((2.0 * mu_ab + _C1) * (2.0 * sigma_ab + _C2)) / (
        (mu_a_sq + mu_b_sq + _C1) * (sigma_a_sq + sigma_b_sq + _C2) + _EPS
    )
    return torch.clamp((1.0 - ssim) / 2, min=0, max=1).mean(dim=(1, 2, 3))


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
