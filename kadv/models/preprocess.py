"""How a depth network wants its input and how its output comes back, differentiably.

One :class:`Preprocess` describes what a family's image processor does (size, aspect handling,
multiple, padding, normalisation, resampling) and what its ``post_process_depth_estimation``
does to bring the prediction back to the image (undo the padding, resize). Both directions are
written with kornia and torch so the gradient reaches the image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from kornia.enhance import normalize
from kornia.geometry.transform import resize

from kadv.checks import check_shape

__all__ = ["NetworkLayout", "Preprocess", "constrain_to_multiple", "resized_shape"]

# ZoeDepth pads each side by int(sqrt(side / 2) * 3) pixels before resizing (its processor's rule)
_ZOEDEPTH_PAD_FACTOR = 3


def constrain_to_multiple(value: float, multiple: int) -> int:
    """Round to the nearest multiple (never to 0), as Hugging Face's DPT processor does."""
    rounded = round(value / multiple) * multiple
    return int(rounded if rounded >= multiple else math.ceil(value / multiple) * multiple)


def resized_shape(
    height: int, width: int, size: tuple[int, int], keep_aspect_ratio: bool, multiple: int
) -> tuple[int, int]:
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
class NetworkLayout:
    """Where an image of ``size`` (H, W) lies in the network input, so the output can come back.

    Attributes:
        size: the image (H, W).
        source_pad: (top/bottom, left/right) reflect padding added at the image's resolution.
        network_pad: (top, bottom, left, right) zero padding added at the network's resolution.
        network_size: the network input (h, w), padding included.
    """

    size: tuple[int, int]
    source_pad: tuple[int, int] = (0, 0)
    network_pad: tuple[int, int, int, int] = (0, 0, 0, 0)
    network_size: tuple[int, int] = (0, 0)

    def network_K(self, K: torch.Tensor) -> torch.Tensor:
        """The intrinsics of the network input, (3, 3) or (B, 3, 3) as ``K`` is, from the image's:
        its reflect padding, its resize and its zero padding applied to the focal lengths and the
        principal point (pixel corners at integers, as :func:`kadv.geometry.fov_intrinsics` has them).

        Examples:
            >>> K = torch.tensor([[100.0, 0.0, 32.0], [0.0, 100.0, 24.0], [0.0, 0.0, 1.0]])
            >>> NetworkLayout((48, 64), (0, 0), (2, 2, 0, 0), (100, 128)).network_K(K)  # resized x2, padded
            tensor([[200.,   0.,  64.],
                    [  0., 200.,  50.],
                    [  0.,   0.,   1.]])
        """
        (height, width), (pad_h, pad_w) = self.size, self.source_pad
        top, bottom, left, right = self.network_pad
        scale_y = (self.network_size[0] - top - bottom) / (height + 2 * pad_h)
        scale_x = (self.network_size[1] - left - right) / (width + 2 * pad_w)
        to_network = [[scale_x, 0.0, pad_w * scale_x + left], [0.0, scale_y, pad_h * scale_y + top], [0.0, 0.0, 1.0]]
        return torch.tensor(to_network, dtype=K.dtype, device=K.device) @ K


@dataclass(frozen=True)
class Preprocess:
    """How a model wants its input (B, 3, H, W) in [0, 1] and how its output comes back.

    Attributes:
        size: the target (height, width); None keeps the image's size (GLPN).
        keep_aspect_ratio: scale both axes by the factor of the axis that changes least.
        multiple: round the resized sides to the nearest multiple of this.
        floor_multiple: round the sides down to a multiple of this (GLPN's ``size_divisor``).
        pad_multiple: zero-pad the normalised input, centred, up to a multiple of this (DPT's
            ``do_pad`` with ``size_divisor``); the padding is cropped from the output.
        reflect_pad: ZoeDepth's reflect padding of int(sqrt(side / 2) * 3) before resizing,
            cropped from the output.
        mean, std: per-channel normalisation; None for none.
        normalize_first: normalise before resizing (DepthPro) instead of after.
        interpolation: "bilinear" or "bicubic" for the input.
        antialias: resample as PIL does (the PIL-backend processors) rather than plain torch
            interpolation (torchvision backends with ``antialias=False``, ZoeDepth, kadv-tiny).
        align_corners: passed to the input's interpolation (ZoeDepth resizes with True).
        output_interpolation: how the prediction is resized back, as the family's post-processing does.
    """

    size: tuple[int, int] | None
    keep_aspect_ratio: bool = False
    multiple: int = 1
    floor_multiple: int = 1
    pad_multiple: int = 1
    reflect_pad: bool = False
    mean: tuple[float, float, float] | None = (0.485, 0.456, 0.406)
    std: tuple[float, float, float] | None = (0.229, 0.224, 0.225)
    normalize_first: bool = False
    interpolation: str = "bicubic"
    antialias: bool = False
    align_corners: bool | None = None
    output_interpolation: str = "bilinear"

    def network_size(self, height: int, width: int) -> tuple[int, int]:
        """The (h, w) an image of (height, width), padding included, is resized to."""
        if self.size is None:
            return tuple(
                max(self.floor_multiple, side // self.floor_multiple * self.floor_multiple) for side in (height, width)
            )
        return resized_shape(height, width, self.size, self.keep_aspect_ratio, self.multiple)

    def normalize(self, rgb: torch.Tensor) -> torch.Tensor:
        """(rgb - mean) / std per channel for rgb (B, 3, h, w); unchanged without a mean."""
        if self.mean is None or self.std is None:
            return rgb
        # made on the host and copied without waiting for the device (three numbers)
        as_tensor = lambda values: torch.tensor(values, dtype=rgb.dtype).to(rgb.device, non_blocking=True)
        return normalize(rgb, as_tensor(self.mean), as_tensor(self.std))

    def _resize(self, x: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
        if tuple(x.shape[-2:]) == shape:
            return x
        if self.antialias:
            # torch's antialiased kernels follow PIL's; kornia's antialias blurs with a Gaussian instead
            return F.interpolate(x, shape, mode=self.interpolation, align_corners=self.align_corners, antialias=True)
        return resize(x, shape, interpolation=self.interpolation, align_corners=self.align_corners)

    def to_network(self, rgb: torch.Tensor) -> tuple[torch.Tensor, NetworkLayout]:
        """The network input (B, 3, h, w) for rgb (B, 3, H, W) in [0, 1], and its layout."""
        check_shape(rgb, "B 3 H W", "rgb")
        height, width = rgb.shape[-2:]
        x = self.normalize(rgb) if self.normalize_first else rgb
        source_pad = (0, 0)
        if self.reflect_pad:
            source_pad = (
                int(math.sqrt(height / 2) * _ZOEDEPTH_PAD_FACTOR),
                int(math.sqrt(width / 2) * _ZOEDEPTH_PAD_FACTOR),
            )
            x = F.pad(x, (source_pad[1], source_pad[1], source_pad[0], source_pad[0]), mode="reflect")
        x = self._resize(x, self.network_size(*x.shape[-2:]))
        x = x if self.normalize_first else self.normalize(x)
        network_pad = (0, 0, 0, 0)
        if self.pad_multiple > 1:
            extra = [-side % self.pad_multiple for side in x.shape[-2:]]
            network_pad = (extra[0] // 2, extra[0] - extra[0] // 2, extra[1] // 2, extra[1] - extra[1] // 2)
            x = F.pad(x, (network_pad[2], network_pad[3], network_pad[0], network_pad[1]))
        return x, NetworkLayout((height, width), source_pad, network_pad, tuple(x.shape[-2:]))

    def from_network(self, out: torch.Tensor, layout: NetworkLayout) -> torch.Tensor:
        """The prediction (B, 1, H, W) at the image's size from the network's (B, 1, h, w).

        The network's output may differ in size from its input (DINOv2 DPT heads predict 16 pixels
        per 14-pixel patch), so its padding is cropped in proportion.
        """
        check_shape(out, "B 1 h w", "out")
        if any(layout.network_pad):
            (h_out, w_out), (h_in, w_in) = out.shape[-2:], layout.network_size
            top, bottom, left, right = (
                round(pad * scale)
                for pad, scale in zip(layout.network_pad, (h_out / h_in, h_out / h_in, w_out / w_in, w_out / w_in))
            )
            out = out[..., top : h_out - bottom, left : w_out - right]
        pad_h, pad_w = layout.source_pad
        padded = (layout.size[0] + 2 * pad_h, layout.size[1] + 2 * pad_w)
        if tuple(out.shape[-2:]) != padded:
            out = resize(out, padded, interpolation=self.output_interpolation, align_corners=False)
        return out[..., pad_h : padded[0] - pad_h, pad_w : padded[1] - pad_w]
