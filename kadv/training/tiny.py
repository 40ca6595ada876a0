"""Training the embedded models on generated rooms: kadv-tiny and kadv-tiny-dpt with a
scale-and-shift-invariant disparity loss, kadv-tiny-metric with a loss on metric log depth."""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from kadv.datasets import HELD_OUT_SEED, TRAINING_BAKE, RoomMix, ViewBatch, render_procedural_views
from kadv.device import resolve_device
from kadv.losses import ssi_loss
from kadv.losses.ssi import gradient_matching
from kadv.models.base import DepthModel
from kadv.models.tiny import (
    DEFAULT_CHANNELS,
    TINY_PREPROCESS,
    KadvTiny,
    TinyDepthNet,
    load_kadv_tiny,
)
from kadv.models.tiny_dpt import load_kadv_tiny_dpt, tiny_dpt_model, tiny_dpt_network
from kadv.render import BakeConfig
from kadv.scenes.procedural import CORRIDOR_SHARE, HALL_SHARE
from kadv.training.evaluation import evaluate

__all__ = [
    "ARCHITECTURES",
    "AUGMENTATIONS",
    "TARGETS",
    "TinyTrainConfig",
    "fit",
    "load_soup",
    "metric_log_loss",
    "render_training_views",
    "soup",
    "train_tiny",
]

ARCHITECTURES = ("unet", "dpt")
AUGMENTATIONS = ("basic", "strong")
TARGETS = ("disparity", "metric")


@dataclass
class TinyTrainConfig:
    """Everything that determines a training run of an embedded model (same config, same weights).

    ``architecture`` is "unet" (kadv-tiny, ``channels`` wide) or "dpt" (kadv-tiny-dpt, a small
    hybrid DPT); ``target`` is "disparity" (relative, the scale-and-shift-invariant loss) or
    "metric" (the U-Net's kadv-tiny-metric: depth in metres, :func:`metric_log_loss`). ``seed``
    draws the training rooms (``render_procedural_views``), the batches and the augmentation;
    ``val_seed`` the validation rooms. ``furnished_share`` of the rooms are
    furnished rooms, the rest box rooms; ``corridor_share`` and ``hall_share`` of the furnished
    rooms are corridors and halls (both 0: the rooms of the generator before it drew them).
    ``attack_view_share`` of the views are drawn as the attack draws init views (eye height, level
    gaze), and a ``squeeze_share`` of the rooms are seen through wider frames squeezed to the
    model's input size (as the model squeezes wide images); a ``baked_share`` of the rooms are lit
    by their baked global illumination (``bake``: ``TRAINING_BAKE`` unless given, a BakeConfig or
    its keys) instead of random direct shading. ``stairs_share``, ``sun_share``,
    ``glazing_share``, ``trim_share`` and ``round_share`` pass to
    :func:`~kadv.scenes.procedural_room` (flights of stairs, a sun through a window, glazed walls,
    mouldings, round things). ``augment`` is "basic" (flips, gain, colour balance) or
    "strong" (also a tone curve, saturation and a zoom).
    ``device`` trains on the CPU (bit-identical weights for one config) or a CUDA device (faster;
    its weights differ in the last bits). ``init_weights`` continues from an earlier run's weights
    (a kadv-tiny file, whose channels win over ``channels``, or a kadv-tiny-dpt directory), so a
    long training can be done, and reproduced, in stages. ``soup_with`` names earlier weights of
    the same architecture that the trained weights are averaged with at the end (a uniform model
    soup; Wortsman et al., 2022): weights along one fine-tuning path average into a model better
    than each.
    """

    seed: int = 0
    train_views: int = 4000
    val_views: int = 200
    val_seed: int = 1
    steps: int = 18000
    batch_size: int = 16
    lr: float = 2e-3
    weight_decay: float = 1e-4
    gradient_weight: float = 0.5
    channels: tuple[int, ...] = DEFAULT_CHANNELS
    init_weights: str | None = None
    architecture: str = "unet"
    furnished_share: float = 0.75
    corridor_share: float = CORRIDOR_SHARE
    hall_share: float = HALL_SHARE
    attack_view_share: float = 0.0
    squeeze_share: float = 0.0
    baked_share: float = 0.0
    stairs_share: float = 0.0
    sun_share: float = 0.0
    glazing_share: float = 0.0
    trim_share: float = 0.0
    round_share: float = 0.0
    bake: BakeConfig | dict = field(default_factory=lambda: TRAINING_BAKE)
    augment: str = "basic"
    device: str = "cpu"
    soup_with: list[str] = field(default_factory=list)
    target: str = "disparity"

    def __post_init__(self) -> None:
        # checked here, before the minutes of rendering that come first in train_tiny
        for name in ("train_views", "val_views", "steps", "batch_size"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"train.{name} must be an integer >= 1, got {value!r}")
        if not (math.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"train.lr must be positive, got {self.lr}")
        for name in ("weight_decay", "gradient_weight"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"train.{name} must be >= 0, got {getattr(self, name)}")
        if not self.channels or any(not isinstance(c, int) or c < 1 for c in self.channels):
            raise ValueError(f"train.channels must be positive integers, got {list(self.channels)}")
        if self.architecture not in ARCHITECTURES:
            raise ValueError(f"train.architecture must be one of {', '.join(ARCHITECTURES)}, got {self.architecture!r}")
        if self.target not in TARGETS:
            raise ValueError(f"train.target must be one of {', '.join(TARGETS)}, got {self.target!r}")
        if self.target == "metric" and self.architecture != "unet":
            raise ValueError("train.target=metric trains the U-Net (kadv_tiny_metric): set train.architecture=unet")
        if self.target == "metric" and self.augment == "strong":
            raise ValueError("train.augment=strong zooms, which changes the depth a view's pixels imply: use basic")
        if self.augment not in AUGMENTATIONS:
            raise ValueError(f"train.augment must be one of {', '.join(AUGMENTATIONS)}, got {self.augment!r}")
        if HELD_OUT_SEED in (self.seed, self.val_seed) or self.seed == self.val_seed:
            raise ValueError(
                f"train.seed ({self.seed}) and train.val_seed ({self.val_seed}) must differ from each other and "
                f"from {HELD_OUT_SEED}, the seed of the held-out rooms the benchmark measures on"
            )
        if isinstance(self.bake, dict):
            try:
                self.bake = replace(TRAINING_BAKE, **self.bake)
            except TypeError:
                unknown = sorted(set(self.bake) - {f.name for f in fields(BakeConfig)})
                raise ValueError(f"train.bake has no key(s) {', '.join(unknown)}") from None
            except ValueError as error:  # BakeConfig names its keys as the renderer's node
                raise ValueError(str(error).replace("render.bake.", "train.bake.")) from None
        self.mix().check("train.")
        try:
            resolve_device(self.device)
        except ValueError as error:
            raise ValueError(f"train.{error}") from None
        for key, path in [("init_weights", self.init_weights)] + [("soup_with", p) for p in self.soup_with]:
            if path is not None and not Path(path).expanduser().exists():
                raise FileNotFoundError(f"train.{key}: no such weights file or directory: {path}")

    def mix(self) -> RoomMix:
        """The rooms and views this run trains on."""
        return RoomMix(**{f.name: getattr(self, f.name) for f in fields(RoomMix)})


def _augment(
    rgb: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor, generator: torch.Generator, strong: bool = False
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Flip, gain and colour balance; ``strong`` adds a tone curve, saturation and a zoom."""
    flip = torch.rand(rgb.shape[0], generator=generator) < 0.5
    rgb, depth, mask = (torch.where(flip[:, None, None, None], x.flip(-1), x) for x in (rgb, depth, mask))
    gain = 0.7 + 0.6 * torch.rand(rgb.shape[0], 1, 1, 1, generator=generator)
    bias = 0.1 * (torch.rand(rgb.shape[0], 3, 1, 1, generator=generator) - 0.5)
    rgb = rgb * gain + bias
    if strong:  # drawn after the basic draws, so a basic run draws what it drew before
        rgb, depth, mask = _tone_and_zoom(rgb.clamp(0, 1), depth, mask, generator)
    return rgb.clamp(0, 1), depth, mask


def _tone_and_zoom(
    rgb: torch.Tensor, depth: torch.Tensor, mask: torch.Tensor, generator: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A gamma of 0.7-1.4 and saturation of 0.6-1.3 (renderers and cameras tone-map differently),
    then a crop of 1/1.3 to all of the view, resized back: a narrower field of view, as lenses differ."""
    n = rgb.shape[0]
    gamma = torch.exp(0.35 * (2 * torch.rand(n, 1, 1, 1, generator=generator) - 1))
    saturation = 0.6 + 0.7 * torch.rand(n, 1, 1, 1, generator=generator)
    rgb = rgb.clamp_min(1e-6) ** gamma
    grey = rgb.mean(dim=1, keepdim=True)
    rgb = grey + saturation * (rgb - grey)
    scale = 1 / (1 + 0.3 * torch.rand(n, generator=generator))
    shift = (1 - scale)[:, None] * (2 * torch.rand(n, 2, generator=generator) - 1)
    theta = torch.zeros(n, 2, 3)
    theta[:, 0, 0], theta[:, 1, 1], theta[:, :, 2] = scale, scale, shift
    grid = torch.nn.functional.affine_grid(theta, list(rgb.shape), align_corners=False)
    sample = lambda x, mode: torch.nn.functional.grid_sample(x, grid, mode=mode, align_corners=False)
    # depth and its mask by the nearest sample, so no pixel blends a near and a far surface
    return sample(rgb, "bilinear"), sample(depth, "nearest"), sample(mask.float(), "nearest") > 0.5


def fit(model: DepthModel, train: ViewBatch, config: TinyTrainConfig, progress: bool = True) -> list[float]:
    """Optimise ``model.network`` in place on ``train`` for ``config.steps`` steps; returns the loss per step.

    kadv-tiny takes the views (at its input size) normalised; other models through their own preprocessing.
    """
    network = model.network
    device = resolve_device(config.device)
    # channels-last convolutions train about 30% faster on CPU (oneDNN).
    network.train().requires_grad_(True).to(device, memory_format=torch.channels_last)
    optimiser = torch.optim.AdamW(network.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=config.lr, total_steps=config.steps)
    generator = torch.Generator().manual_seed(config.seed)
    losses: list[float] = []
    bar = tqdm(range(config.steps), desc=f"training {model.name}", disable=not progress)
    for _ in bar:
        index = torch.randint(len(train.rgb), (config.batch_size,), generator=generator)
        # drawn on the CPU whatever the device, so a seed draws the same batches everywhere
        rgb, depth, mask = _augment(
            train.rgb[index], train.depth[index], train.mask[index], generator, config.augment == "strong"
        )
        rgb, depth, mask = rgb.to(device), depth.to(device), mask.to(device)
        loss = _LOSSES[config.target](_predict(model, rgb), depth, mask, config.gradient_weight)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        losses.append(loss.item())
        bar.set_postfix(loss=f"{np.mean(losses[-50:]):.4f}")
    network.cpu()
    model.freeze()
    return losses


def metric_log_loss(
    prediction: torch.Tensor, gt_depth: torch.Tensor, mask: torch.Tensor, gradient_weight: float = 0.0, scales: int = 4
) -> torch.Tensor:
    """Mean |log(prediction) - log(depth)| over valid pixels, plus ``gradient_weight`` times the
    multi-scale gradient matching of that residual: a metric depth prediction's loss, no alignment.

    Examples:
        >>> depth = 1.0 + torch.arange(64.0, dtype=torch.float64).reshape(1, 1, 8, 8) / 16
        >>> mask = torch.ones_like(depth, dtype=torch.bool)
        >>> metric_log_loss(depth, depth, mask, 0.5).item(), round(metric_log_loss(2 * depth, depth, mask).item(), 6)
        (0.0, 0.693147)
    """
    weight = mask.to(prediction.dtype)
    count = weight.sum(dim=(1, 2, 3)).clamp_min(1.0)
    residual = weight * (prediction.clamp_min(1e-6).log() - gt_depth.clamp_min(1e-6).log())
    loss = residual.abs().sum(dim=(1, 2, 3)) / count
    if gradient_weight > 0:
        loss = loss + gradient_weight * gradient_matching(residual, mask, scales)
    return loss.mean()


_LOSSES = {"disparity": ssi_loss, "metric": metric_log_loss}


def _predict(model: DepthModel, rgb: torch.Tensor) -> torch.Tensor:
    """(B, 1, H, W) predictions for views (B, 3, H, W), differentiable in the weights."""
    if isinstance(model, KadvTiny):  # its views are at its input size: normalising is all its preprocessing does
        return model.predict(model.preprocess.normalize(rgb).contiguous(memory_format=torch.channels_last))
    return model(rgb)


def render_training_views(config: TinyTrainConfig, progress: bool = True) -> tuple[ViewBatch, ViewBatch]:
    """The training and validation views ``config`` names, at kadv-tiny's working size."""
    height, width = TINY_PREPROCESS.size
    train = render_procedural_views(config.train_views, config.seed, height, width, config.mix(), progress=progress)
    val = render_procedural_views(config.val_views, config.val_seed, height, width, config.mix(), progress=progress)
    return train, val


def _load(path: str, architecture: str) -> DepthModel:
    if architecture == "dpt":
        return load_kadv_tiny_dpt(Path(path).expanduser())
    return load_kadv_tiny(path, output_kind=None)  # either kind: a stage may start from the other


def _initial_model(config: TinyTrainConfig) -> DepthModel:
    torch.manual_seed(config.seed)  # here, so the initial weights depend on the seed alone
    kind = "depth" if config.target == "metric" else "disparity"
    if config.init_weights is not None:
        model = _load(config.init_weights, config.architecture)
        # kadv-tiny's features start kadv-tiny-metric well: its head learns the other kind
        return KadvTiny(model.network, kind) if isinstance(model, KadvTiny) else model
    if config.architecture == "dpt":
        return tiny_dpt_model(tiny_dpt_network())
    return KadvTiny(TinyDepthNet(tuple(config.channels)), kind)


def load_soup(model: DepthModel, paths: list[str], architecture: str) -> list[dict[str, torch.Tensor]]:
    """The weights at ``paths``, for :func:`soup`; a ValueError naming the path unless shaped like ``model``'s."""
    # loading builds networks, which draws initial weights; the caller's seeded generator must not see that
    with torch.random.fork_rng(devices=[]):
        states = [_load(path, architecture).network.state_dict() for path in paths]
    shapes = {name: value.shape for name, value in model.network.state_dict().items()}
    for path, state in zip(paths, states):
        if {name: value.shape for name, value in state.items()} != shapes:
            raise ValueError(f"train.soup_with: {path} is not shaped like the trained {model.name} (other channels?)")
    return states


def soup(model: DepthModel, states: list[dict[str, torch.Tensor]]) -> None:
    """Replace ``model``'s floating-point weights by their mean with ``states`` (from :func:`load_soup`)."""
    with torch.no_grad():
        for name, value in model.network.state_dict().items():
            if value.is_floating_point():
                value.copy_(torch.stack([value] + [state[name] for state in states]).mean(0))


def train_tiny(
    config: TinyTrainConfig, progress: bool = True, views: tuple[ViewBatch, ViewBatch] | None = None
) -> tuple[DepthModel, dict[str, object]]:
    """Render the data (unless ``views`` gives what :func:`render_training_views` would), train,
    and return the model with a log (losses, delta1, timings)."""
    model = _initial_model(config)
    # a soup of other channels is refused here, not after the minutes of rendering and training
    soup_states = load_soup(model, config.soup_with, config.architecture)
    start = time.perf_counter()
    train, val = render_training_views(config, progress) if views is None else views
    render_seconds = time.perf_counter() - start
    start = time.perf_counter()
    losses = fit(model, train, config, progress)
    train_seconds = time.perf_counter() - start
    if soup_states:
        soup(model, soup_states)
    log = {
        "config": asdict(config),
        "render_seconds": render_seconds,
        "train_seconds": train_seconds,
        "final_loss": float(np.mean(losses[-100:])),
        "val_delta1": evaluate(model, val),
        "output_kind": model.output_kind,
        # a metric model's delta1 as it predicts, unaligned (None for a relative one)
        "val_delta1_metric": evaluate(model, val, alignment="none") if model.output_kind == "depth" else None,
        "losses": losses,
    }
    return model, log
