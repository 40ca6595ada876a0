"""Depth models: the interface, Hugging Face adapters, your own modules, and the embedded kadv-tiny and kadv-tiny-dpt.

The names below load on first use, so that the preset list (``kadv.models.presets``) is read
without importing torch or transformers.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "DepthModel": "kadv.models.base",
    "HuggingFaceDepthModel": "kadv.models.huggingface",
    "EMBEDDED": "kadv.models.presets",
    "KadvTiny": "kadv.models.tiny",
    "ModelWeightsUnavailable": "kadv.models.huggingface",
    "ModuleDepthModel": "kadv.models.custom",
    "NetworkLayout": "kadv.models.preprocess",
    "PRESETS": "kadv.models.presets",
    "Preprocess": "kadv.models.preprocess",
    "Preset": "kadv.models.presets",
    "TinyDepthNet": "kadv.models.tiny",
    "check_depth_model": "kadv.models.custom",
    "load_custom": "kadv.models.custom",
    "load_huggingface": "kadv.models.huggingface",
    "load_kadv_tiny": "kadv.models.tiny",
    "load_kadv_tiny_dpt": "kadv.models.tiny_dpt",
    "load_model": "kadv.models.registry",
    "preset_table": "kadv.models.presets",
    "resized_shape": "kadv.models.preprocess",
    "save_kadv_tiny": "kadv.models.tiny",
    "save_kadv_tiny_dpt": "kadv.models.tiny_dpt",
    "wrap_model": "kadv.models.custom",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'kadv.models' has no attribute {name!r}")
    return getattr(importlib.import_module(_EXPORTS[name]), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])
