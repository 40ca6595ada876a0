"""VGG-16 feature extractor in torchvision's layout (torchvision has no CPU build here).

Module indices match ``torchvision.models.vgg16().features`` so its state dict loads as is.
"""

from __future__ import annotations

import os
from pathlib import Path

import torch
from torch import nn

from kadv.errors import WeightsUnavailable

__all__ = ["VGG16_FILENAME", "VGG16_TAPS", "VGG16_URL", "load_vgg16_state_dict", "vgg16_features"]

VGG16_URL = "https://download.pytorch.org/models/vgg16-397923af.pth"
VGG16_FILENAME = "vgg16-397923af.pth"
# Indices of relu1_2, relu2_2, relu3_3, relu4_3 in torchvision's vgg16().features.
VGG16_TAPS = (3, 8, 15, 22)
_CONFIG = (64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512)


def vgg16_features() -> nn.Sequential:
    """The VGG-16 convolutional layers up to relu4_3 (indices 0..22), randomly initialised.

    Examples:
        >>> features = vgg16_features()
        >>> len(features), features(torch.zeros(1, 3, 32, 32)).shape  # up to relu4_3: 512 channels at 1/8
        (23, torch.Size([1, 512, 4, 4]))
    """
    layers: list[nn.Module] = []
    channels = 3
    for item in _CONFIG:
        if item == "M":
            layers.append(nn.MaxPool2d(kernel_size=2, stride=2))
        else:
            layers += [nn.Conv2d(channels, item, kernel_size=3, padding=1), nn.ReLU(inplace=False)]
            channels = item
    return nn.Sequential(*layers)


def load_vgg16_state_dict(path: str | Path | None = None) -> dict[str, torch.Tensor]:
    """The ``features.*`` tensors of a torchvision-layout VGG-16 checkpoint, keys without the prefix.

    Resolution: ``path`` -> ``$TORCH_HOME/hub/checkpoints/vgg16-397923af.pth`` -> download.

    Raises:
        FileNotFoundError: an explicit ``path`` that does not exist.
        WeightsUnavailable: no local copy and the download failed (offline), saying how to provide it.

    Examples:
        >>> import tempfile
        >>> state = {f"features.{k}": v for k, v in vgg16_features().state_dict().items()}
        >>> with tempfile.TemporaryDirectory() as folder:
        ...     torch.save(state | {"classifier.0.weight": torch.zeros(1)}, Path(folder) / "vgg16.pth")
        ...     loaded = load_vgg16_state_dict(Path(folder) / "vgg16.pth")
        >>> sorted(loaded)[:2], len(loaded)  # features only, without the prefix: 10 convolutions
        (['0.bias', '0.weight'], 20)
    """
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"VGG-16 weights not found: {path}")
        state = torch.load(path, map_location="cpu", weights_only=True)
    else:
        torch_home = Path(os.environ.get("TORCH_HOME", Path.home() / ".cache" / "torch"))
        cached = torch_home / "hub" / "checkpoints" / VGG16_FILENAME
        if cached.is_file():
            state = torch.load(cached, map_location="cpu", weights_only=True)
        else:
            try:
                state = torch.hub.load_state_dict_from_url(VGG16_URL, map_location="cpu", progress=False)
            except Exception as error:  # urllib raises several kinds when offline
                raise WeightsUnavailable(
                    f"VGG-16 weights for the perceptual loss are not available: no file at {cached} and the "
                    f"download from {VGG16_URL} failed ({type(error).__name__}). Copy {VGG16_FILENAME} there, "
                    "pass loss.vgg_weights=/path/to/file, or use the weight-free loss (loss=ssim)."
                ) from error
    features = {k.removeprefix("features."): v for k, v in state.items() if k.startswith("features.")}
    if not features:
        raise ValueError("VGG-16 state dict has no 'features.*' entries (not a torchvision-layout checkpoint)")
    return features
