"""Depth models: the interface, Hugging Face adapters, and the embedded kadv-tiny."""
from __future__ import annotations

from kadv.models.base import DepthModel
from kadv.models.preprocess import NetworkLayout, Preprocess, resized_shape
from kadv.models.custom import ModuleDepthModel, check_depth_model, load_custom, wrap_model
from kadv.models.huggingface import HuggingFaceDepthModel, ModelWeightsUnavailable, load_huggingface
from kadv.models.registry import PRESETS, Preset, load_model, preset_table
from kadv.models.tiny import KadvTiny, TinyDepthNet, load_kadv_tiny, save_kadv_tiny

__all__ = [
    "PRESETS",
    "DepthModel",
    "HuggingFaceDepthModel",
    "KadvTiny",
    "ModelWeightsUnavailable",
    "ModuleDepthModel",
    "NetworkLayout",
    "Preprocess",
    "Preset",
    "TinyDepthNet",
    "check_depth_model",
    "load_custom",
    "load_huggingface",
    "load_kadv_tiny",
    "load_model",
    "preset_table",
    "resized_shape",
    "save_kadv_tiny",
    "wrap_model",
]
