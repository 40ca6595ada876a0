"""Tiny random checkpoints of every transformers depth family kadv attacks, with the image-processor
settings each family's real checkpoints carry (shrunk to the tiny networks' sizes)."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from transformers import (
    BeitConfig,
    BitConfig,
    DepthAnythingConfig,
    DepthAnythingForDepthEstimation,
    DepthProConfig,
    DepthProForDepthEstimation,
    Dinov2Config,
    DPTConfig,
    DPTForDepthEstimation,
    GLPNConfig,
    GLPNForDepthEstimation,
    Tipsv2DptConfig,
    Tipsv2DptForDepthEstimation,
    ZoeDepthConfig,
    ZoeDepthForDepthEstimation,
)

__all__ = ["FAMILIES", "Family", "save_family"]

VIT = {
    "hidden_size": 32,
    "num_hidden_layers": 4,
    "num_attention_heads": 2,
    "intermediate_size": 64,
    "image_size": 64,
    "patch_size": 16,
}
NECK = {"neck_hidden_sizes": [8, 16, 32, 32], "fusion_hidden_size": 16, "reassemble_factors": [4, 2, 1, 0.5]}
IMAGENET = {"image_mean": [0.485, 0.456, 0.406], "image_std": [0.229, 0.224, 0.225]}
HALF = {"image_mean": [0.5] * 3, "image_std": [0.5] * 3}


def _dinov2(out_indices: list[int], layers: int = 4) -> Dinov2Config:
    return Dinov2Config(
        hidden_size=32,
        num_hidden_layers=layers,
        num_attention_heads=2,
        intermediate_size=64,
        image_size=56,
        patch_size=14,
        apply_layernorm=True,
        reshape_hidden_states=False,
        out_indices=out_indices,
    )


def _dpt() -> torch.nn.Module:
    return DPTForDepthEstimation(DPTConfig(**VIT, backbone_out_indices=[0, 1, 2, 3], **NECK))


def _dpt_hybrid() -> torch.nn.Module:
    bit = BitConfig(
        embedding_size=32,
        hidden_sizes=[64, 64, 64],
        depths=[1, 1, 1],
        layer_type="bottleneck",
        num_groups=8,
        global_padding="same",
        out_features=["stage1", "stage2", "stage3"],
        embedding_dynamic_padding=True,
    )
    return DPTForDepthEstimation(
        DPTConfig(
            **VIT,
            is_hybrid=True,
            backbone_config=bit,
            backbone_out_indices=[0, 1, 2, 3],
            neck_hidden_sizes=[64, 64, 32, 32],
            fusion_hidden_size=32,
            reassemble_factors=[1, 1, 1, 0.5],
            readout_type="project",
            backbone_featmap_shape=[1, 64, 4, 4],
        )
    )


def _dpt_beit() -> torch.nn.Module:
    beit = BeitConfig(**VIT, out_indices=[1, 2, 3, 4], use_relative_position_bias=True, reshape_hidden_states=False)
    return DPTForDepthEstimation(DPTConfig(backbone_config=beit, hidden_size=32, **NECK))


def _dpt_dinov2() -> torch.nn.Module:
    # the DINOv2 depth heads project the fused features through a fixed 256-channel convolution
    return DPTForDepthEstimation(
        DPTConfig(
            backbone_config=_dinov2([1, 2, 3, 4]),
            hidden_size=32,
            neck_hidden_sizes=[8, 16, 32, 32],
            fusion_hidden_size=256,
            reassemble_factors=[4, 2, 1, 0.5],
            add_projection=True,
            readout_type="project",
            head_in_index=-1,
        )
    )


def _zoedepth() -> torch.nn.Module:
    beit = BeitConfig(**VIT, out_indices=[1, 2, 3, 4], use_relative_position_bias=True, reshape_hidden_states=False)
    bins = [
        {"name": "nyu", "n_bins": 8, "min_depth": 1e-3, "max_depth": 10.0},
        {"name": "kitti", "n_bins": 8, "min_depth": 1e-3, "max_depth": 80.0},
    ]
    return ZoeDepthForDepthEstimation(
        ZoeDepthConfig(
            backbone_config=beit,
            **NECK,
            bottleneck_features=16,
            num_relative_features=8,
            bin_embedding_dim=16,
            num_attractors=[4, 2, 2, 2],
            num_patch_transformer_layers=4,
            patch_transformer_hidden_size=128,
            patch_transformer_intermediate_size=128,
            patch_transformer_num_attention_heads=2,
            bin_configurations=bins,
        )
    )


def _depth_anything(out_indices: list[int], **extra: Any) -> torch.nn.Module:
    dino = _dinov2(out_indices, layers=8)
    return DepthAnythingForDepthEstimation(
        DepthAnythingConfig(
            backbone_config=dino,
            reassemble_hidden_size=32,
            patch_size=14,
            neck_hidden_sizes=[8, 16, 32, 32],
            fusion_hidden_size=16,
            head_hidden_size=8,
            **extra,
        )
    )


def _glpn() -> torch.nn.Module:
    return GLPNForDepthEstimation(
        GLPNConfig(
            num_encoder_blocks=4,
            depths=[1, 1, 1, 1],
            sr_ratios=[8, 4, 2, 1],
            hidden_sizes=[8, 16, 32, 64],
            num_attention_heads=[1, 1, 2, 2],
            mlp_ratios=[2, 2, 2, 2],
            decoder_hidden_size=16,
        )
    )


def _depth_pro() -> torch.nn.Module:
    # input side = patch_size / min(scaled_images_ratios) = 64 / 0.5 = 128 (1536 for the real one)
    dino = {
        "model_type": "dinov2",
        "hidden_size": 32,
        "num_hidden_layers": 2,
        "num_attention_heads": 2,
        "intermediate_size": 64,
        "patch_size": 16,
    }
    return DepthProForDepthEstimation(
        DepthProConfig(
            fusion_hidden_size=16,
            patch_size=64,
            intermediate_hook_ids=[1, 0],
            intermediate_feature_dims=[16, 16],
            scaled_images_ratios=[0.5, 1],
            scaled_images_overlap_ratios=[0.0, 0.25],
            scaled_images_feature_dims=[16, 16],
            use_fov_model=True,
            num_fov_head_layers=1,
            image_model_config=dino,
            patch_model_config=dino,
            fov_model_config=dino,
        )
    )


def _centre_field_of_view(network: torch.nn.Module) -> None:
    """A random field-of-view head can predict a negative angle, and DepthPro then clamps every
    depth to its bound (a flat map, as with transformers 5.17): centre the angle on 60 degrees."""
    with torch.no_grad():
        network.fov_model.head.layers[-1].bias.fill_(60.0)


def _tipsv2_dpt() -> torch.nn.Module:
    backbone = {
        "model_type": "tipsv2_vision_model",
        "hidden_size": 32,
        "num_hidden_layers": 4,
        "num_attention_heads": 2,
        "image_size": 56,
        "patch_size": 14,
        "out_indices": [1, 2, 3, 4],
        "reshape_hidden_states": False,
        "apply_layernorm": True,
    }
    return Tipsv2DptForDepthEstimation(
        Tipsv2DptConfig(
            backbone_config=backbone, neck_hidden_sizes=[8, 16, 32, 32], fusion_hidden_size=16, num_depth_bins=16
        )
    )


@dataclass(frozen=True)
class Family:
    """A tiny checkpoint: how to build it, its preprocessor_config.json (None: none, so kadv uses the
    family's defaults), the output kind kadv must give it, whether transformers' own image
    processor runs here (DepthPro's and TIPSv2's need torchvision, which has no CPU build), and what
    the family needs set after the random weights are spread (None: nothing)."""

    build: Callable[[], torch.nn.Module]
    processor: dict[str, Any] | None
    kind: str
    processor_runs: bool = True
    settle: Callable[[torch.nn.Module], None] | None = None


_DPT_PROCESSOR = {"image_processor_type": "DPTImageProcessor", "resample": 3}
FAMILIES = {
    "dpt_vit": Family(_dpt, {**_DPT_PROCESSOR, "size": {"height": 64, "width": 64}, **HALF}, "disparity"),
    "dpt_hybrid": Family(_dpt_hybrid, {**_DPT_PROCESSOR, "size": {"height": 64, "width": 64}, **HALF}, "disparity"),
    "dpt_beit": Family(
        _dpt_beit,
        {
            **_DPT_PROCESSOR,
            "size": {"height": 64, "width": 64},
            "keep_aspect_ratio": True,
            "ensure_multiple_of": 16,
            **HALF,
        },
        "disparity",
    ),
    "dpt_dinov2": Family(
        _dpt_dinov2, {**_DPT_PROCESSOR, "do_resize": False, "do_pad": True, "size_divisor": 14, **IMAGENET}, "depth"
    ),
    "zoedepth": Family(
        _zoedepth,
        {
            "image_processor_type": "ZoeDepthImageProcessor",
            "size": {"height": 64, "width": 96},
            "keep_aspect_ratio": True,
            "ensure_multiple_of": 32,
            "do_pad": True,
            "resample": 2,
            **HALF,
        },
        "depth",
    ),
    "depth_anything_v1": Family(
        lambda: _depth_anything([5, 6, 7, 8]),
        {
            **_DPT_PROCESSOR,
            "size": {"height": 56, "width": 56},
            "keep_aspect_ratio": True,
            "ensure_multiple_of": 14,
            **IMAGENET,
        },
        "disparity",
    ),
    "depth_anything_v2": Family(
        lambda: _depth_anything([2, 4, 6, 8]),
        {
            **_DPT_PROCESSOR,
            "size": {"height": 70, "width": 70},
            "keep_aspect_ratio": True,
            "ensure_multiple_of": 14,
            **IMAGENET,
        },
        "disparity",
    ),
    "depth_anything_v2_metric": Family(
        lambda: _depth_anything([2, 4, 6, 8], depth_estimation_type="metric", max_depth=20),
        {
            **_DPT_PROCESSOR,
            "size": {"height": 56, "width": 56},
            "keep_aspect_ratio": True,
            "ensure_multiple_of": 14,
            **IMAGENET,
        },
        "depth",
    ),
    "glpn": Family(_glpn, {"image_processor_type": "GLPNImageProcessor", "size_divisor": 32, "resample": 2}, "depth"),
    "depth_pro": Family(_depth_pro, None, "depth", processor_runs=False, settle=_centre_field_of_view),
    "tipsv2_dpt": Family(
        _tipsv2_dpt,
        {"image_processor_type": "Tipsv2DptImageProcessor", "size": {"height": 56, "width": 56}},
        "depth",
        processor_runs=False,
    ),
}


def _spread_weights(network: torch.nn.Module) -> torch.nn.Module:
    """He-normal weights and small random biases in every linear and convolution layer.

    At transformers' initialisation a tiny network predicts a nearly constant map (a range of 1e-9
    for DPT), too flat for a comparison to mean anything; these weights keep activations near unit
    scale, so the prediction depends on the image.
    """
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for module in network.modules():
            if isinstance(module, (torch.nn.Linear, torch.nn.Conv2d, torch.nn.ConvTranspose2d)):
                fan_in = module.weight[0].numel()
                if isinstance(module, torch.nn.ConvTranspose2d):
                    fan_in = module.weight.shape[0] * module.weight[0, 0].numel()
                module.weight.normal_(0.0, math.sqrt(2.0 / fan_in), generator=generator)
                if module.bias is not None:
                    module.bias.normal_(0.0, 0.1, generator=generator)
    return network


def save_family(name: str, directory: Path) -> Path:
    """Build family ``name`` with seed 0 and save it (and its processor settings) to ``directory``."""
    family = FAMILIES[name]
    torch.manual_seed(0)
    network = _spread_weights(family.build())
    if family.settle is not None:
        family.settle(network)
    network.save_pretrained(directory)
    if family.processor is not None:
        (directory / "preprocessor_config.json").write_text(json.dumps(family.processor))
    return directory
