"""``load_model``: presets, hub ids, local directories, and the embedded kadv-tiny model."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from huggingface_hub import try_to_load_from_cache

from kadv.models.base import DepthModel
from kadv.models.huggingface import load_huggingface
from kadv.models.tiny import TINY_PREPROCESS, load_kadv_tiny

__all__ = ["PRESETS", "Preset", "load_model", "preset_table", "weights_cached"]

@dataclass(frozen=True)
class Preset:
    """A named checkpoint.

    Attributes:
        hub_id: its Hugging Face id ("" for the embedded kadv-tiny).
        family: its transformers model type.
        output_kind: "disparity" or "depth".
        input_size: the network input (height, width) its processor aims for.
    """

    hub_id: str
    family: str
    output_kind: str
    input_size: tuple[int, int]


PRESETS = {
    "midas_dpt_large": Preset("Intel/dpt-large", "dpt", "disparity", (384, 384)),
    "midas_dpt_hybrid": Preset("Intel/dpt-hybrid-midas", "dpt", "disparity", (384, 384)),
    "zoedepth_nk": Preset("Intel/zoedepth-nyu-kitti", "zoedepth", "depth", (384, 512)),
    "depth_anything_v1_small": Preset("LiheYoung/depth-anything-small-hf", "depth_anything", "disparity", (518, 518)),
    "depth_anything_v1_base": Preset("LiheYoung/depth-anything-base-hf", "depth_anything", "disparity", (518, 518)),
    "depth_anything_v1_large": Preset("LiheYoung/depth-anything-large-hf", "depth_anything", "disparity", (518, 518)),
    "depth_anything_v2_small": Preset("depth-anything/Depth-Anything-V2-Small-hf", "depth_anything", "disparity",
                                      (518, 518)),
    "depth_anything_v2_base": Preset("depth-anything/Depth-Anything-V2-Base-hf", "depth_anything", "disparity",
                                     (518, 518)),
    "depth_anything_v2_large": Preset("depth-anything/Depth-Anything-V2-Large-hf", "depth_anything", "disparity",
                                      (518, 518)),
    "depth_anything_v2_metric_indoor_small": Preset(
        "depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf", "depth_anything", "depth", (518, 518)),
    "depth_anything_v2_metric_indoor_base": Preset(
        "depth-anything/Depth-Anything-V2-Metric-Indoor-Base-hf", "depth_anything", "depth", (518, 518)),
    "depth_anything_v2_metric_indoor_large": Preset(
        "depth-anything/Depth-Anything-V2-Metric-Indoor-Large-hf", "depth_anything", "depth", (518, 518)),
    "depth_anything_v2_metric_outdoor_small": Preset(
        "depth-anything/Depth-Anything-V2-Metric-Outdoor-Small-hf", "depth_anything", "depth", (518, 518)),
    "depth_anything_v2_metric_outdoor_base": Preset(
        "depth-anything/Depth-Anything-V2-Metric-Outdoor-Base-hf", "depth_anything", "depth", (518, 518)),
    "depth_anything_v2_metric_outdoor_large": Preset(
        "depth-anything/Depth-Anything-V2-Metric-Outdoor-Large-hf", "depth_anything", "depth", (518, 518)),
}
KADV_TINY = Preset("", "kadv_tiny", "disparity", TINY_PREPROCESS.size)


def weights_cached(hub_id: str) -> bool:
    """Whether the Hugging Face cache holds ``hub_id``'s config (offline: it only reads the disk)."""
    return isinstance(try_to_load_from_cache(hub_id, "config.json"), str)


def preset_table() -> list[dict[str, str]]:
    """One row per preset (kadv_tiny first): name, hub id, family, output kind, input size, cached."""
    rows = [{"name": "kadv_tiny", "hub id": "(embedded)", "family": KADV_TINY.family, "output": KADV_TINY.output_kind,
             "input": "x".join(map(str, KADV_TINY.input_size)), "weights": "in the package"}]
    for name, preset in PRESETS.items():
        rows.append({"name": name, "hub id": preset.hub_id, "family": preset.family, "output": preset.output_kind,
                     "input": "x".join(map(str, preset.input_size)),
                     "weights": "cached" if weights_cached(preset.hub_id) else "not cached"})
    return rows


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
        return load_huggingface(str(weights), name=name, hub_id=PRESETS[name].hub_id if name in PRESETS else name)
    if Path(name).expanduser().is_dir():
        return load_huggingface(name, name=Path(name).name)
    if name.startswith(("/", "./", "../", "~")):
        raise FileNotFoundError(f"no such model directory: {name}")
    if name in PRESETS:
        return load_huggingface(PRESETS[name].hub_id, name=name, hub_id=PRESETS[name].hub_id)
    if "/" not in name:
        raise ValueError(f"unknown model {name!r}: not a preset ({', '.join(sorted(PRESETS))}, kadv_tiny), "
                         "not a local directory, and not a Hugging Face id (owner/name)")
    return load_huggingface(name, name=name, hub_id=name)
