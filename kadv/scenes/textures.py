"""Texture images: loading from files and converting colours to the renderer's display space."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

__all__ = ["image_to_rgba", "linear_to_srgb", "load_hdr_image", "load_image", "srgb_to_linear"]


def linear_to_srgb(linear: np.ndarray) -> np.ndarray:
    """Encode linear reflectances as sRGB so constant colours match sRGB textures on screen."""
    linear = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1.0 / 2.4) - 0.055)


def srgb_to_linear(srgb: np.ndarray) -> np.ndarray:
    """Decode sRGB values in [0, 1] to linear ones: the inverse of :func:`linear_to_srgb`."""
    srgb = np.clip(np.asarray(srgb, np.float64), 0.0, 1.0)
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def image_to_rgba(image: Image.Image | np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(H, W, 3) float32 RGB in [0, 1] and (H, W) alpha if the image has one."""
    if isinstance(image, Image.Image):
        has_alpha = image.mode in ("RGBA", "LA") or (image.mode == "P" and "transparency" in image.info)
        image = np.asarray(image.convert("RGBA" if has_alpha else "RGB"))
    array = np.asarray(image)
    scale = 255.0 if array.dtype == np.uint8 else (65535.0 if array.dtype == np.uint16 else 1.0)
    array = array.astype(np.float32) / scale
    if array.ndim == 2:
        array = array[:, :, None]
    if array.shape[2] in (2, 4):
        alpha, array = array[:, :, -1], array[:, :, :-1]
    else:
        alpha = None
    if array.shape[2] == 1:
        array = np.repeat(array, 3, axis=2)
    return np.ascontiguousarray(array[:, :, :3]), alpha


def load_image(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a texture file as (H, W, 3) float32 RGB and optional (H, W) alpha.

    Raises:
        FileNotFoundError: if the file does not exist.
        ValueError: if the file cannot be decoded as an image.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"texture file not found: {path}")
    try:
        with Image.open(path) as image:
            image.load()
            return image_to_rgba(image)
    except OSError as error:
        raise ValueError(f"texture file {path} could not be decoded: {error}") from error


def _read_exr(path: Path) -> np.ndarray:
    """(H, W, C) the first part of an OpenEXR file: its RGB(A) channels, else its first channel."""
    import OpenEXR

    with OpenEXR.File(str(path)) as file:
        channels = file.channels()
        for name in ("RGB", "RGBA", "Y"):
            if name in channels:
                return np.asarray(channels[name].pixels)
        return np.asarray(next(iter(channels.values())).pixels)


def load_hdr_image(path: Path) -> np.ndarray:
    """(H, W, 3) float32 linear radiance of an environment map: floating-point files (.exr, .hdr,
    .pfm) as stored, 8-bit images decoded from sRGB.

    Raises:
        ValueError: if no installed reader decodes the file.
    """
    import imageio.v3 as iio

    try:
        # imageio reads OpenEXR only through plugins that download a library or need OpenCV
        image = _read_exr(path) if path.suffix.lower() == ".exr" else np.asarray(iio.imread(path))
    except Exception as error:  # each reader raises its own kinds
        raise ValueError(f"environment map {path} could not be read ({type(error).__name__}: {error})") from error
    if image.dtype.kind == "f":
        image = image.astype(np.float32)
        image = np.repeat(image[:, :, None], 3, axis=2) if image.ndim == 2 else image[:, :, :3]
        return np.ascontiguousarray(np.maximum(np.nan_to_num(image), 0.0))
    rgb, _ = image_to_rgba(image)
    return srgb_to_linear(rgb).astype(np.float32)
