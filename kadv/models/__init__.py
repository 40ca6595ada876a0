"""Depth models: the interface, Hugging Face adapters, Marigold through diffusers, your own modules,
and the embedded kadv-tiny and kadv-tiny-dpt.

The names below load on first use, so that the preset list (``kadv.models.presets``) is read
without importing torch or transformers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from kadv._lazy import lazy_exports

_EXPORTS = {
    "DepthModel": "kadv.models.base",
    "HuggingFaceDepthModel": "kadv.models.huggingface",
    "EMBEDDED": "kadv.models.presets",
    "INTRINSICS": "kadv.models.base",
    "KadvTiny": "kadv.models.tiny",
    "MarigoldDepthModel": "kadv.models.marigold",
    "MarigoldSettings": "kadv.models.marigold",
    "ModelWeightsUnavailable": "kadv.models.huggingface",
    "ModuleDepthModel": "kadv.models.custom",
    "NetworkLayout": "kadv.models.preprocess",
    "PassCount": "kadv.models.counting",
    "PRESETS": "kadv.models.presets",
    "Preprocess": "kadv.models.preprocess",
    "Preset": "kadv.models.presets",
    "TinyDepthNet": "kadv.models.tiny",
    "check_depth_model": "kadv.models.custom",
    "check_intrinsics": "kadv.models.base",
    "count_passes": "kadv.models.counting",
    "load_custom": "kadv.models.custom",
    "load_huggingface": "kadv.models.huggingface",
    "load_kadv_tiny": "kadv.models.tiny",
    "load_kadv_tiny_dpt": "kadv.models.tiny_dpt",
    "load_marigold": "kadv.models.marigold",
    "load_model": "kadv.models.registry",
    "preset_table": "kadv.models.presets",
    "resized_shape": "kadv.models.preprocess",
    "save_kadv_tiny": "kadv.models.tiny",
    "save_kadv_tiny_dpt": "kadv.models.tiny_dpt",
    "wrap_model": "kadv.models.custom",
}

if TYPE_CHECKING:  # the same names, for type checkers and the API reference
    from kadv.models.base import INTRINSICS, DepthModel, check_intrinsics
    from kadv.models.counting import PassCount, count_passes
    from kadv.models.custom import ModuleDepthModel, check_depth_model, load_custom, wrap_model
    from kadv.models.huggingface import HuggingFaceDepthModel, ModelWeightsUnavailable, load_huggingface
    from kadv.models.marigold import MarigoldDepthModel, MarigoldSettings, load_marigold
    from kadv.models.preprocess import NetworkLayout, Preprocess, resized_shape
    from kadv.models.presets import EMBEDDED, PRESETS, Preset, preset_table
    from kadv.models.registry import load_model
    from kadv.models.tiny import KadvTiny, TinyDepthNet, load_kadv_tiny, save_kadv_tiny
    from kadv.models.tiny_dpt import load_kadv_tiny_dpt, save_kadv_tiny_dpt

__all__ = [
    "EMBEDDED",
    "INTRINSICS",
    "PRESETS",
    "DepthModel",
    "HuggingFaceDepthModel",
    "KadvTiny",
    "MarigoldDepthModel",
    "MarigoldSettings",
    "ModelWeightsUnavailable",
    "ModuleDepthModel",
    "NetworkLayout",
    "PassCount",
    "Preprocess",
    "Preset",
    "TinyDepthNet",
    "check_depth_model",
    "check_intrinsics",
    "count_passes",
    "load_custom",
    "load_huggingface",
    "load_kadv_tiny",
    "load_kadv_tiny_dpt",
    "load_marigold",
    "load_model",
    "preset_table",
    "resized_shape",
    "save_kadv_tiny",
    "save_kadv_tiny_dpt",
    "wrap_model",
]

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
