"""Depth models: the interface, Hugging Face adapters, and the embedded kadv-tiny."""
from __future__ import annotations

from kadv.models.base import DepthModel, Preprocess, resized_shape
from kadv.models.huggingface import HuggingFaceDepthModel, ModelWeightsUnavailable, load_huggingface
from kadv.models.registry import PRESETS, load_model
from kadv.models.tiny import KadvTiny, TinyDepthNet, load_kadv_tiny, save_kadv_tiny

__all__ = [
    "PRESETS",
    "DepthModel",
    "HuggingFaceDepthModel",
    "KadvTiny",
    "ModelWeightsUnavailable",
    "Preprocess",
    "TinyDepthNet",
    "load_huggingface",
    "load_kadv_tiny",
    "load_model",
    "resized_shape",
    "save_kadv_tiny",
]
