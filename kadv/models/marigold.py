"""Marigold through diffusers: ``MarigoldDepthPipeline``'s steps, written so the gradient reaches the image.

diffusers runs its pipelines under ``no_grad``. :class:`MarigoldDepthModel` holds the same VAE,
UNet and scheduler and repeats ``__call__``'s steps in the same order: the long edge resized with
antialias to the processing resolution, replicate padding to the VAE's multiple, the VAE's latent
mode, the UNet on the empty-text embedding (made once from the checkpoint's own tokenizer and text
encoder), the scheduler's steps, decoding, unpadding and the resize back to the image. Its noise is
one fixed draw per latent shape, shared by every view in a batch, so a view's prediction depends
on neither the batch nor the call. diffusers is an extra: ``pip install 'kadv[diffusers]'``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass, fields

import torch
import torch.nn.functional as F

from kadv.errors import MissingExtra
from kadv.models.base import DepthModel

__all__ = [
    "MARIGOLD_SETTINGS",
    "NOISES",
    "PRESET_SETTINGS",
    "MarigoldDepthModel",
    "MarigoldSettings",
    "load_marigold",
    "marigold_kind",
]

# the starting latent: a fixed Gaussian draw (Marigold) or its mean (the one-step E2E-FT fine-tunes)
NOISES = ("gaussian", "zeros")
_INSTALL = "pip install 'kadv[diffusers]'"


@dataclass(frozen=True)
class MarigoldSettings:
    """How a Marigold pipeline runs (``model.steps``, ...); None takes the checkpoint's default.

    Attributes:
        steps: denoising steps.
        processing_resolution: the long edge the image is resized to (0: the image's own size).
        ensemble_size: predictions from as many noise draws, aligned and combined by diffusers'
            non-differentiable fit; above 1 for evaluation only (gradient methods refuse it).
        noise: the starting latent, ``gaussian`` (a draw fixed by ``seed``) or ``zeros``.
        seed: the noise draw's seed; ensemble member m uses ``seed + m``.
    """

    steps: int | None = None
    processing_resolution: int | None = None
    ensemble_size: int = 1
    noise: str = "gaussian"
    seed: int = 0

    def __post_init__(self) -> None:
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"model.steps must be at least 1, got {self.steps}")
        if self.processing_resolution is not None and self.processing_resolution < 0:
            raise ValueError(
                f"model.processing_resolution must be 0 (native) or positive, got {self.processing_resolution}"
            )
        if self.ensemble_size < 1:
            raise ValueError(f"model.ensemble_size must be at least 1, got {self.ensemble_size}")
        if self.noise not in NOISES:
            raise ValueError(f"model.noise must be one of {', '.join(NOISES)}, got {self.noise!r}")


# the model node's keys that are Marigold's settings
MARIGOLD_SETTINGS = tuple(field.name for field in fields(MarigoldSettings))
# a preset's own settings where they are not the defaults: the E2E-FT fine-tune takes one step from zeros
PRESET_SETTINGS = {"marigold_e2e_ft_depth": {"steps": 1, "processing_resolution": 768, "noise": "zeros"}}


def marigold_kind(prediction_type: str | None, scale_invariant: bool, shift_invariant: bool) -> str:
    """The output kind (:data:`kadv.losses.KINDS`) a Marigold checkpoint's config declares.

    Raises:
        ValueError: a combination no kind describes.
    """
    kinds = {
        ("depth", True, True): "affine_depth",
        ("depth", True, False): "scale_depth",
        ("depth", False, False): "depth",
        ("disparity", True, True): "disparity",
    }
    key = (prediction_type or "depth", bool(scale_invariant), bool(shift_invariant))
    if key not in kinds:
        raise ValueError(
            f"a Marigold checkpoint with prediction_type={key[0]}, scale_invariant={key[1]}, "
            f"shift_invariant={key[2]} has no output kind kadv knows"
        )
    return kinds[key]


class MarigoldDepthModel(DepthModel):
    """A Marigold depth pipeline's networks behind the :class:`DepthModel` interface.

    Its input is the image itself (its own resize and padding are part of :meth:`predict`); its
    output lies in [0, 1] at the image's size.
    """

    def __init__(self, pipeline: object, name: str, settings: MarigoldSettings = MarigoldSettings()) -> None:
        config = pipeline.config
        super().__init__(
            None, marigold_kind(config.prediction_type, config.scale_invariant, config.shift_invariant), name
        )
        self.vae, self.unet, self.scheduler = pipeline.vae, pipeline.unet, pipeline.scheduler
        self.settings = settings
        self.steps = settings.steps or config.default_denoising_steps
        resolution = settings.processing_resolution
        self.resolution = config.default_processing_resolution if resolution is None else resolution
        if self.steps is None or self.resolution is None:
            missing = "model.steps" if self.steps is None else "model.processing_resolution"
            raise ValueError(f"model {name!r}: the checkpoint sets no default for {missing}; set it")
        self.vae_scale = pipeline.vae_scale_factor
        if self.resolution % self.vae_scale:
            raise ValueError(
                f"model.processing_resolution must be a multiple of {self.vae_scale} (the VAE's), got {self.resolution}"
            )
        self.register_buffer("empty_text", _empty_text_embedding(pipeline.tokenizer, pipeline.text_encoder))
        self._invariance = (bool(config.scale_invariant), bool(config.shift_invariant))
        self.freeze()

    @property
    def differentiable(self) -> bool:
        """Whether the prediction's gradient is the pipeline's: one ensemble member only."""
        return self.settings.ensemble_size == 1

    def inference_settings(self) -> dict:
        return {**asdict(self.settings), "steps": self.steps, "processing_resolution": self.resolution}

    def predict(self, pixel_values: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        """(B, 1, H, W) in [0, 1] for rgb (B, 3, H, W) in [0, 1]."""
        height, width = pixel_values.shape[-2:]
        x = pixel_values * 2.0 - 1.0
        if self.resolution > 0:
            longest = max(height, width)
            size = (height * self.resolution // longest, width * self.resolution // longest)
            x = F.interpolate(x, size, mode="bilinear", antialias=True)
        pad_h, pad_w = -x.shape[-2] % self.vae_scale, -x.shape[-1] % self.vae_scale
        x = F.pad(x, (0, pad_w, 0, pad_h), mode="replicate")
        image_latent = self.vae.encode(x).latent_dist.mode() * self.vae.config.scaling_factor
        members = [self._member(image_latent, self.settings.seed + m) for m in range(self.settings.ensemble_size)]
        prediction = members[0] if len(members) == 1 else self._ensemble(torch.stack(members))
        prediction = prediction[..., : prediction.shape[-2] - pad_h, : prediction.shape[-1] - pad_w]
        return F.interpolate(prediction, (height, width), mode="bilinear")

    def _member(self, image_latent: torch.Tensor, seed: int) -> torch.Tensor:
        """One prediction (B, 1, h, w) in [0, 1] at the padded processing size."""
        from diffusers.utils.torch_utils import randn_tensor

        batch = image_latent.shape[0]
        # one generator per view, all seeded alike: every view draws the same noise, whatever the batch
        generators = [torch.Generator().manual_seed(seed) for _ in range(batch)]
        latent = randn_tensor(image_latent.shape, generator=generators, device=image_latent.device)
        latent = latent.to(image_latent.dtype) * (self.settings.noise == "gaussian")
        text = self.empty_text.expand(batch, -1, -1)
        self.scheduler.set_timesteps(self.steps, device=image_latent.device)
        for t in self.scheduler.timesteps:
            noise = self.unet(
                torch.cat([image_latent, latent], dim=1), t, encoder_hidden_states=text, return_dict=False
            )[0]
            latent = self.scheduler.step(noise, t, latent, generator=generators).prev_sample
        decoded = self.vae.decode(latent / self.vae.config.scaling_factor, return_dict=False)[0]
        return (decoded.mean(dim=1, keepdim=True).clamp(-1.0, 1.0) + 1.0) / 2.0

    @torch.no_grad()
    def _ensemble(self, members: torch.Tensor) -> torch.Tensor:
        """diffusers' alignment and median of ``members`` (E, B, 1, h, w), per view: (B, 1, h, w)."""
        from diffusers import MarigoldDepthPipeline

        return torch.cat(
            [MarigoldDepthPipeline.ensemble_depth(members[:, b], *self._invariance)[0] for b in range(members.shape[1])]
        )


def _empty_text_embedding(tokenizer: object, text_encoder: torch.nn.Module) -> torch.Tensor:
    """The UNet's conditioning (1, T, C): the checkpoint's encoding of the empty prompt, as the pipeline makes it."""
    ids = tokenizer(
        "", padding="do_not_pad", max_length=tokenizer.model_max_length, truncation=True, return_tensors="pt"
    ).input_ids
    with torch.no_grad():
        return text_encoder(ids)[0].detach()


@contextlib.contextmanager
def _quiet_loading() -> Iterator[None]:
    """diffusers' and transformers' loading bars off, as kadv's own loading shows none."""
    from diffusers.utils import logging as diffusers_logging
    from transformers.utils import logging as transformers_logging

    libraries = [lib for lib in (diffusers_logging, transformers_logging) if lib.is_progress_bar_enabled()]
    for library in libraries:
        library.disable_progress_bar()
    try:
        yield
    finally:
        for library in libraries:
            library.enable_progress_bar()


def load_marigold(
    source: str, name: str | None = None, hub_id: str | None = None, settings: MarigoldSettings = MarigoldSettings()
) -> MarigoldDepthModel:
    """A Marigold depth checkpoint (a hub id or a ``save_pretrained`` directory) as a depth model.

    Raises:
        MissingExtra: diffusers is not installed; the message says what to install.
        ModelWeightsUnavailable: the weights are neither there, cached nor downloadable.
    """
    try:
        from diffusers import MarigoldDepthPipeline
    except ImportError as error:
        raise MissingExtra(f"model {name or source!r} needs diffusers: {_INSTALL}") from error
    from kadv.models.huggingface import resolve_weights

    def load(location: str, local_only: bool) -> MarigoldDepthModel:
        with _quiet_loading():
            pipeline = MarigoldDepthPipeline.from_pretrained(location, local_files_only=local_only)
        return MarigoldDepthModel(pipeline, name or source, settings)

    return resolve_weights(source, load, name, hub_id)
