"""A tiny random Marigold depth pipeline built offline from configs: a UNet, a VAE (8x, as Stable
Diffusion's), a DDIM scheduler as Marigold v1.1's, a small CLIP text encoder, and a CLIP tokenizer
written from a minimal vocabulary. ``marigold_pipeline`` takes other network sizes (the cost
benchmark builds one of Marigold's own size)."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import torch
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer

try:
    from diffusers import AutoencoderKL, DDIMScheduler, MarigoldDepthPipeline, UNet2DConditionModel
except ImportError as error:  # a missing tool fails with the command that installs it
    raise ImportError("the Marigold tests need diffusers: pip install -e '.[diffusers]' (make test does)") from error

__all__ = ["FULL_UNET", "FULL_VAE", "TINY_UNET", "TINY_VAE", "marigold_pipeline", "save_tiny_marigold"]

TINY_UNET = {
    "block_out_channels": (16, 32),
    "down_block_types": ("CrossAttnDownBlock2D", "DownBlock2D"),
    "up_block_types": ("UpBlock2D", "CrossAttnUpBlock2D"),
    "layers_per_block": 1,
    "norm_num_groups": 8,
    "attention_head_dim": 4,
    "cross_attention_dim": 32,
}
TINY_VAE = {"block_out_channels": (8, 8, 16, 16), "layers_per_block": 1, "norm_num_groups": 4}
# Stable Diffusion 2's networks, which Marigold fine-tunes (its UNet takes 8 channels: image and depth latents)
FULL_UNET = {
    "block_out_channels": (320, 640, 1280, 1280),
    "down_block_types": ("CrossAttnDownBlock2D",) * 3 + ("DownBlock2D",),
    "up_block_types": ("UpBlock2D",) + ("CrossAttnUpBlock2D",) * 3,
    "layers_per_block": 2,
    "attention_head_dim": (5, 10, 20, 20),
    "cross_attention_dim": 1024,
    "use_linear_projection": True,
}
FULL_VAE = {"block_out_channels": (128, 256, 512, 512), "layers_per_block": 2}
# Marigold v1.1's scheduler (its scheduler_config.json)
_SCHEDULER = {
    "beta_schedule": "scaled_linear",
    "beta_start": 0.00085,
    "beta_end": 0.012,
    "clip_sample": False,
    "set_alpha_to_one": False,
    "steps_offset": 1,
    "prediction_type": "v_prediction",
    "timestep_spacing": "trailing",
}
_VOCAB = ["<|startoftext|>", "<|endoftext|>", "a</w>", "room</w>"]


def marigold_pipeline(
    unet: dict = TINY_UNET,
    vae: dict = TINY_VAE,
    steps: int = 1,
    resolution: int = 64,
    scale_invariant: bool = True,
    shift_invariant: bool = True,
    seed: int = 0,
) -> MarigoldDepthPipeline:
    """A random Marigold depth pipeline with networks of these sizes (diffusers' config keys)."""
    torch.manual_seed(seed)
    blocks = len(vae["block_out_channels"])
    autoencoder = AutoencoderKL(
        down_block_types=("DownEncoderBlock2D",) * blocks,
        up_block_types=("UpDecoderBlock2D",) * blocks,
        latent_channels=4,
        **vae,
    )
    text_dim = unet["cross_attention_dim"]
    text_config = CLIPTextConfig(
        vocab_size=len(_VOCAB),
        hidden_size=text_dim,
        intermediate_size=2 * text_dim,
        num_attention_heads=4,
        num_hidden_layers=2,
        max_position_embeddings=8,
        bos_token_id=0,
        eos_token_id=1,
        pad_token_id=1,
    )
    with tempfile.TemporaryDirectory() as folder:
        vocab, merges = Path(folder) / "vocab.json", Path(folder) / "merges.txt"
        vocab.write_text(json.dumps({token: index for index, token in enumerate(_VOCAB)}))
        merges.write_text("#version: 0.2\n")
        tokenizer = CLIPTokenizer(str(vocab), str(merges), model_max_length=8)
    return MarigoldDepthPipeline(
        unet=UNet2DConditionModel(in_channels=8, out_channels=4, **unet),
        vae=autoencoder,
        scheduler=DDIMScheduler(**_SCHEDULER),
        text_encoder=CLIPTextModel(text_config),
        tokenizer=tokenizer,
        prediction_type="depth",
        scale_invariant=scale_invariant,
        shift_invariant=shift_invariant,
        default_denoising_steps=steps,
        default_processing_resolution=resolution,
    )


def save_tiny_marigold(folder: Path, **options: object) -> Path:
    """:func:`marigold_pipeline`'s tiny pipeline saved as a checkpoint folder (``save_pretrained``)."""
    marigold_pipeline(**options).save_pretrained(folder)
    return folder
