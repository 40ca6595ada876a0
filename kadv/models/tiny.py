"""kadv-tiny: a compact U-Net predicting relative disparity, trained on procedural rooms only, and
kadv-tiny-metric, the same network trained to predict metric depth.

Their weights ship in ``kadv/models/weights/`` so everything runs offline.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file
from torch import nn
from torch.nn import functional as F

from kadv.models.base import DepthModel
from kadv.models.preprocess import Preprocess

__all__ = ["TINY_METRIC_WEIGHTS", "TINY_WEIGHTS", "KadvTiny", "TinyDepthNet", "load_kadv_tiny", "save_kadv_tiny"]

TINY_WEIGHTS = Path(__file__).parent / "weights" / "kadv_tiny.safetensors"
TINY_METRIC_WEIGHTS = Path(__file__).parent / "weights" / "kadv_tiny_metric.safetensors"
# what each output kind's network is called
_NAMES = {"disparity": "kadv_tiny", "depth": "kadv_tiny_metric"}
DEFAULT_CHANNELS = (16, 32, 64, 128, 256)
# The training resolution, to which every image is resized whatever its aspect (as DPT-Large's
# processor squeezes images into its square): the network has seen no other size, and on held-out
# generated 16:9 views squeezing scores higher than keeping the aspect (delta1 0.771 vs 0.756).
TINY_PREPROCESS = Preprocess(size=(128, 160), keep_aspect_ratio=False, multiple=32, interpolation="bilinear")


def _block(c_in: int, c_out: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, stride=stride, padding=1, bias=False),
        nn.GroupNorm(8, c_out),
        nn.GELU(),
        nn.Conv2d(c_out, c_out, 3, padding=1, bias=False),
        nn.GroupNorm(8, c_out),
        nn.GELU(),
    )


class TinyDepthNet(nn.Module):
    """U-Net: (B, 3, h, w) normalised RGB, h and w multiples of 32 -> (B, 1, h, w) positive
    disparity or depth (in metres), as it was trained."""

    def __init__(self, channels: tuple[int, ...] = DEFAULT_CHANNELS) -> None:
        super().__init__()
        self.channels = tuple(channels)
        self.encoder = nn.ModuleList(
            [_block(3, channels[0], stride=2)] + [_block(a, b, stride=2) for a, b in itertools.pairwise(channels)]
        )
        self.decoder = nn.ModuleList([_block(b + a, a) for a, b in itertools.pairwise(channels)])
        self.head = nn.Sequential(
            nn.Conv2d(channels[0], channels[0], 3, padding=1), nn.GELU(), nn.Conv2d(channels[0], 1, 1)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for block in self.encoder:
            x = block(x)
            skips.append(x)
        x = skips.pop()
        for block in reversed(self.decoder):
            skip = skips.pop()
            x = block(
                torch.cat([F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False), skip], 1)
            )
        x = F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False)
        return F.softplus(self.head(x))


class KadvTiny(DepthModel):
    """kadv-tiny behind the :class:`DepthModel` interface: output relative ``disparity``
    (kadv_tiny) or metric ``depth`` (kadv_tiny_metric)."""

    def __init__(self, network: TinyDepthNet, output_kind: str = "disparity") -> None:
        super().__init__(TINY_PREPROCESS, output_kind, _NAMES[output_kind])
        self.network = network
        self.freeze()

    def predict(self, pixel_values: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        return self.network(pixel_values)


def save_kadv_tiny(network: TinyDepthNet, path: str | Path, metadata: dict[str, object] | None = None) -> Path:
    """Write weights (float16 to stay small) with the architecture, the output kind (``disparity``
    unless ``metadata`` names another) and training facts as metadata."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    info = {"channels": json.dumps(list(network.channels)), "output_kind": json.dumps("disparity")}
    info |= {k: json.dumps(v) for k, v in (metadata or {}).items()}
    state = {k: v.detach().to(torch.float16).contiguous() for k, v in network.state_dict().items()}
    save_file(state, str(path), metadata=info)
    return path


def load_kadv_tiny(weights: str | Path | None = None, output_kind: str | None = "disparity") -> KadvTiny:
    """Load kadv-tiny (``output_kind="depth"``: kadv-tiny-metric; None: the kind the weights
    name) from ``weights`` or the copy shipped in the package.

    Raises:
        FileNotFoundError: the weights file does not exist (says how to train it).
        ValueError: the weights predict the other kind.
    """
    expected = output_kind or "disparity"
    shipped = TINY_WEIGHTS if expected == "disparity" else TINY_METRIC_WEIGHTS
    path = Path(weights) if weights is not None else shipped
    if not path.is_file():
        target = "" if expected == "disparity" else " train.target=metric"
        raise FileNotFoundError(
            f"{_NAMES[expected]} weights not found at {path}; train them with kadv-train-tiny{target}"
        )
    with safe_open(str(path), framework="pt") as handle:
        metadata = handle.metadata()
    kind = json.loads(metadata.get("output_kind", '"disparity"'))
    if output_kind is not None and kind != output_kind:
        raise ValueError(f"{path}: these weights predict {kind}, not the {output_kind} of {_NAMES[output_kind]}")
    network = TinyDepthNet(tuple(json.loads(metadata["channels"])))
    network.load_state_dict({k: v.float() for k, v in load_file(str(path)).items()})
    return KadvTiny(network, kind)
