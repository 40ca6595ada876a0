"""The model presets: named checkpoints with their hub id, family, output kind and input size.

Plain data (no torch), so that ``kadv-models`` lists them in well under a second.
"""

from __future__ import annotations

from dataclasses import dataclass

from huggingface_hub import try_to_load_from_cache

__all__ = ["EMBEDDED", "PRESETS", "Preset", "preset_table", "weights_cached"]


@dataclass(frozen=True)
class Preset:
    """A named checkpoint.

    Attributes:
        hub_id: its Hugging Face id ("" for the embedded models).
        family: its transformers model type.
        output_kind: its kind (:data:`kadv.losses.KINDS`); a Marigold checkpoint's config declares it.
        input_size: the network input its processor aims for, e.g. "518x518 keep-aspect /14"; what
            the checkpoint's own preprocessor_config.json says is what kadv uses.
    """

    hub_id: str
    family: str
    output_kind: str
    input_size: str


_DA = "518x518 keep-aspect /14"
_DINOV2_DPT = "image size, padded to /14"
_MARIGOLD = "768 long edge, padded to /8"
PRESETS = {
    "midas_dpt_large": Preset("Intel/dpt-large", "dpt", "disparity", "384x384"),
    "midas_dpt_hybrid": Preset("Intel/dpt-hybrid-midas", "dpt", "disparity", "384x384"),
    "dpt_beit_large_512": Preset("Intel/dpt-beit-large-512", "dpt", "disparity", "512x512"),
    "dpt_beit_large_384": Preset("Intel/dpt-beit-large-384", "dpt", "disparity", "384x384"),
    "dpt_beit_base_384": Preset("Intel/dpt-beit-base-384", "dpt", "disparity", "384x384"),
    **{
        f"dpt_dinov2_{size}_{data}": Preset(f"facebook/dpt-dinov2-{size}-{data}", "dpt", "depth", _DINOV2_DPT)
        for size in ("small", "base", "large")
        for data in ("nyu", "kitti")
    },
    "zoedepth_nk": Preset("Intel/zoedepth-nyu-kitti", "zoedepth", "depth", "384x512 keep-aspect /32, reflect-padded"),
    "glpn_nyu": Preset("vinvino02/glpn-nyu", "glpn", "depth", "image size, floored to /32"),
    "glpn_kitti": Preset("vinvino02/glpn-kitti", "glpn", "depth", "image size, floored to /32"),
    "depth_pro": Preset("apple/DepthPro-hf", "depth_pro", "depth", "1536x1536"),
    "tipsv2_b14_dpt": Preset("google/tipsv2-b14-dpt", "tipsv2_dpt", "depth", "448x448"),
    **{
        f"depth_anything_v1_{size}": Preset(f"LiheYoung/depth-anything-{size}-hf", "depth_anything", "disparity", _DA)
        for size in ("small", "base", "large")
    },
    **{
        f"depth_anything_v2_{size}": Preset(
            f"depth-anything/Depth-Anything-V2-{size.title()}-hf", "depth_anything", "disparity", _DA
        )
        for size in ("small", "base", "large")
    },
    **{
        f"depth_anything_v2_metric_{where}_{size}": Preset(
            f"depth-anything/Depth-Anything-V2-Metric-{where.title()}-{size.title()}-hf", "depth_anything", "depth", _DA
        )
        for where in ("indoor", "outdoor")
        for size in ("small", "base", "large")
    },
    # diffusers pipelines (the kadv[diffusers] extra), loaded by kadv.models.marigold
    "marigold_depth_v1_1": Preset("prs-eth/marigold-depth-v1-1", "marigold", "affine_depth", _MARIGOLD),
    "marigold_e2e_ft_depth": Preset("GonzaloMG/marigold-e2e-ft-depth", "marigold", "affine_depth", _MARIGOLD),
}
# the embedded models, shipped in the package
# (kadv.models.tiny: TINY_PREPROCESS; kadv.models.tiny_dpt: TINY_DPT_PROCESSOR)
EMBEDDED = {
    "kadv_tiny": Preset("", "kadv_tiny", "disparity", "128x160"),
    "kadv_tiny_metric": Preset("", "kadv_tiny", "depth", "128x160"),
    "kadv_tiny_dpt": Preset("", "dpt", "disparity", "160x160"),
}


def weights_cached(hub_id: str) -> bool:
    """Whether the Hugging Face cache holds ``hub_id``'s config, or a diffusers pipeline's index
    (offline: it only reads the disk)."""
    return any(isinstance(try_to_load_from_cache(hub_id, file), str) for file in ("config.json", "model_index.json"))


def preset_table() -> list[dict[str, str]]:
    """One row per preset (the embedded ones first): name, hub id, family, output kind, input size, cached."""
    rows = [
        {
            "name": name,
            "hub id": "(embedded)",
            "family": preset.family,
            "output": preset.output_kind,
            "input": preset.input_size,
            "weights": "in the package",
        }
        for name, preset in EMBEDDED.items()
    ]
    for name, preset in PRESETS.items():
        rows.append(
            {
                "name": name,
                "hub id": preset.hub_id,
                "family": preset.family,
                "output": preset.output_kind,
                "input": preset.input_size,
                "weights": "cached" if weights_cached(preset.hub_id) else "not cached",
            }
        )
    return rows
