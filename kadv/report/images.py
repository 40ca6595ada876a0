"""PNG artefacts, written atomically so an interrupted run never leaves a truncated file."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.colors import Colormap
from PIL import Image

from kadv.io import atomic_write

__all__ = ["depth_colour_map", "depth_range", "save_depth_png", "save_rgb_png"]


def depth_range(depth: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """1st-99th percentile of the valid depths, so a few far pixels do not flatten the room."""
    if not mask.any():
        return 0.0, 1.0
    low, high = np.percentile(depth[mask], [1, 99])
    return float(low), float(max(high, low + 1e-6))


def depth_colour_map() -> Colormap:
    """The depth maps' colour map (turbo), grey where a value is masked (no surface)."""
    return plt.get_cmap("turbo").with_extremes(bad=(0.5, 0.5, 0.5))


def save_rgb_png(path: str | Path, rgb: torch.Tensor) -> Path:
    """Save an image (3, H, W) in [0, 1] as an 8-bit PNG."""
    array = (rgb.detach().clamp(0, 1).permute(1, 2, 0).cpu().numpy() * 255.0 + 0.5).astype(np.uint8)
    return atomic_write(path, lambda tmp: Image.fromarray(array).save(tmp, format="PNG"))


def save_depth_png(
    path: str | Path, depth: torch.Tensor, mask: torch.Tensor | None = None, label: str = "depth [m]"
) -> Path:
    """Save a depth map (1, H, W) colour-mapped with a colour bar; invalid pixels are grey.

    The colour range spans the 1st to 99th percentile of valid depths; values beyond take the end colours.
    """
    values = depth.detach()[0].cpu().numpy().astype(np.float64)
    valid = values > 0 if mask is None else mask.detach()[0].cpu().numpy().astype(bool)
    shown = np.ma.masked_where(~valid, values)
    height, width = values.shape
    dpi = 100
    figure, axis = plt.subplots(figsize=(width / dpi * 1.25 + 0.6, height / dpi + 0.3), dpi=dpi)
    low, high = depth_range(values, valid)
    image = axis.imshow(shown, cmap=depth_colour_map(), interpolation="nearest", vmin=low, vmax=high)
    axis.set_axis_off()
    figure.colorbar(image, ax=axis, fraction=0.046, pad=0.02, label=label, extend="both")

    def write(tmp: Path) -> None:
        figure.savefig(tmp, format="png", bbox_inches="tight")

    try:
        return atomic_write(path, write)
    finally:
        plt.close(figure)
