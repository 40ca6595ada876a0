"""kadv-tiny-dpt: a small DPT (transformers' own ``DPTForDepthEstimation``) predicting relative
disparity, trained on generated rooms only.

It ships as a ``save_pretrained`` directory in ``kadv/models/weights/kadv_tiny_dpt/`` and loads
through the same Hugging Face adapter as any hub checkpoint, so that path runs with trained
weights offline.
"""

from __future__ import annotations

import json
from pathlib import Path

from transformers import BitConfig, DPTConfig, DPTForDepthEstimation, DPTImageProcessorPil

from kadv.models.huggingface import (
    HuggingFaceDepthModel,
    family_preprocess,
    load_huggingface,
)

__all__ = [
    "TINY_DPT_DIR",
    "TINY_DPT_PROCESSOR",
    "load_kadv_tiny_dpt",
    "save_kadv_tiny_dpt",
    "tiny_dpt_model",
    "tiny_dpt_network",
]

TINY_DPT_DIR = Path(__file__).parent / "weights" / "kadv_tiny_dpt"
# transformers' ViT and hybrid DPTs take square token grids, so, like Intel/dpt-large's processor,
# this one resizes to a square without keeping the aspect ratio.
TINY_DPT_PROCESSOR = {
    "do_resize": True,
    "size": {"height": 160, "width": 160},
    "keep_aspect_ratio": False,
    "ensure_multiple_of": 1,
    "resample": 3,
    "do_rescale": True,
    "rescale_factor": 1 / 255,
    "do_normalize": True,
    "image_mean": [0.5, 0.5, 0.5],
    "image_std": [0.5, 0.5, 0.5],
}


def tiny_dpt_network(backbone: str = "hybrid") -> DPTForDepthEstimation:
    """A randomly initialised small DPT: a 4-layer ViT on 16-pixel patches, alone ("vit") or on a
    BiT convolutional stem ("hybrid", as DPT-Hybrid), with a narrow neck and head."""
    vit = {
        "hidden_size": 96,
        "num_hidden_layers": 4,
        "num_attention_heads": 4,
        "intermediate_size": 192,
        "image_size": 160,
        "patch_size": 16,
        "backbone_out_indices": [0, 1, 2, 3],
        "readout_type": "project",
    }
    if backbone == "vit":
        config = DPTConfig(
            **vit,
            neck_hidden_sizes=[32, 48, 64, 96],
            fusion_hidden_size=32,
            reassemble_factors=[4, 2, 1, 0.5],
            use_auxiliary_head=False,
        )
    elif backbone == "hybrid":
        bit = BitConfig(
            embedding_size=32,
            hidden_sizes=[32, 64, 96],
            depths=[1, 1, 1],
            layer_type="bottleneck",
            num_groups=8,
            global_padding="same",
            out_features=["stage1", "stage2", "stage3"],
            embedding_dynamic_padding=True,
        )
        config = DPTConfig(
            **vit,
            is_hybrid=True,
            backbone_config=bit,
            neck_hidden_sizes=[32, 64, 64, 96],
            fusion_hidden_size=32,
            reassemble_factors=[1, 1, 1, 0.5],
            backbone_featmap_shape=[1, 96, 10, 10],
            use_auxiliary_head=False,
        )
    else:
        raise ValueError(f"backbone must be 'vit' or 'hybrid', got {backbone!r}")
    return DPTForDepthEstimation(config)


def tiny_dpt_model(network: DPTForDepthEstimation) -> HuggingFaceDepthModel:
    """``network`` behind the :class:`DepthModel` interface, preprocessed as its saved processor says."""
    return HuggingFaceDepthModel(
        network, family_preprocess(network.config, TINY_DPT_PROCESSOR), "disparity", "kadv_tiny_dpt"
    )


def save_kadv_tiny_dpt(
    network: DPTForDepthEstimation, directory: str | Path, metadata: dict[str, object] | None = None
) -> Path:
    """Write ``network`` and its processor in ``save_pretrained`` layout, with the training facts
    in ``training.json``."""
    directory = Path(directory)
    network.save_pretrained(directory)
    DPTImageProcessorPil(**TINY_DPT_PROCESSOR).save_pretrained(directory)
    (directory / "training.json").write_text(json.dumps(metadata or {}, indent=1, default=str))
    return directory


def load_kadv_tiny_dpt(weights: str | Path | None = None) -> HuggingFaceDepthModel:
    """Load kadv-tiny-dpt from ``weights`` (a ``save_pretrained`` directory) or the shipped copy.

    Raises:
        FileNotFoundError: the directory does not exist (says how to train it).
    """
    directory = Path(weights) if weights is not None else TINY_DPT_DIR
    if not (directory / "config.json").is_file():
        raise FileNotFoundError(
            f"kadv-tiny-dpt weights not found in {directory}; train them with kadv-train-tiny train.architecture=dpt"
        )
    model = load_huggingface(str(directory), name="kadv_tiny_dpt")
    if model.output_kind != "disparity":  # a DPT without a DINOv2 backbone predicts relative disparity
        raise ValueError(f"{directory}: not a kadv-tiny-dpt checkpoint (its output is {model.output_kind})")
    return model
