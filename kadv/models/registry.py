"""``load_model``: presets, hub ids, local directories, and the embedded kadv-tiny model."""
from __future__ import annotations

from pathlib import Path

from kadv.models.base import DepthModel
from kadv.models.huggingface import load_huggingface
from kadv.models.tiny import load_kadv_tiny

__all__ = ["PRESETS", "load_model"]

PRESETS = {
    "midas_dpt_large": "Intel/dpt-large",
    "midas_dpt_hybrid": "Intel/dpt-hybrid-midas",
    "zoedepth_nk": "Intel/zoedepth-nyu-kitti",
    "depth_anything_v1_small": "LiheYoung/depth-anything-small-hf",
    "depth_anything_v1_base": "LiheYoung/depth-anything-base-hf",
    "depth_anything_v1_large": "LiheYoung/depth-anything-large-hf",
    "depth_anything_v2_small": "depth-anything/Depth-Anything-V2-Small-hf",
    "depth_anything_v2_base": "depth-anything/Depth-Anything-V2-Base-hf",
    "depth_anything_v2_large": "depth-anything/Depth-Anything-V2-Large-hf",
}


def load_model(name_or_path: str | Path, weights: str | Path | None = None) -> DepthModel:
    """Load a frozen, eval-mode depth model.

    Args:
        name_or_path: a preset (``midas_dpt_large``, ``zoedepth_nk``, ``depth_anything_v2_small``, ...,
            ``kadv_tiny``), any Hugging Face depth-estimation id, or a local ``save_pretrained`` directory.
        weights: an explicit local directory (or, for ``kadv_tiny``, a weights file) that overrides
            the cache and the hub.

    Raises:
        ModelWeightsUnavailable: weights neither given, cached nor downloadable.
        FileNotFoundError: a path (starting with /, ./, ../ or ~) that is not a directory.
        ValueError: an empty name or an unknown model.
    """
    name = str(name_or_path)
    if not name:
        raise ValueError("model name is empty")
    if name == "kadv_tiny":
        return load_kadv_tiny(weights)
    if weights is not None:
        return load_huggingface(str(weights), name=name, hub_id=PRESETS.get(name, name))
    if Path(name).expanduser().is_dir():
        return load_huggingface(name, name=Path(name).name)
    if name.startswith(("/", "./", "../", "~")):
        raise FileNotFoundError(f"no such model directory: {name}")
    if name in PRESETS:
        return load_huggingface(PRESETS[name], name=name, hub_id=PRESETS[name])
    if "/" not in name:
        raise ValueError(f"unknown model {name!r}: not a preset ({', '.join(sorted(PRESETS))}, kadv_tiny), "
                         "not a local directory, and not a Hugging Face id (owner/name)")
    return load_huggingface(name, name=name, hub_id=name)
