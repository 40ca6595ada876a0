"""``load_model``: presets, hub ids, local directories, and the embedded kadv-tiny model."""

from __future__ import annotations

from pathlib import Path

from kadv.models.base import DepthModel
from kadv.models.presets import PRESETS
from kadv.models.tiny import load_kadv_tiny

__all__ = ["load_model"]


def load_model(name_or_path: str | Path, weights: str | Path | None = None, **settings: object) -> DepthModel:
    """Load a frozen, eval-mode depth model.

    Args:
        name_or_path: a preset (``midas_dpt_large``, ``zoedepth_nk``, ``depth_anything_v2_small``, ...,
            and the embedded ``kadv_tiny``, ``kadv_tiny_metric`` and ``kadv_tiny_dpt``), any Hugging
            Face depth-estimation id, or a local ``save_pretrained`` directory.
        weights: an explicit local directory (or, for ``kadv_tiny*``, a weights file) that overrides
            the cache, the hub, or the shipped copy of an embedded model.
        **settings: a Marigold preset's :class:`~kadv.models.marigold.MarigoldSettings` (``steps``,
            ``processing_resolution``, ``ensemble_size``, ``noise``, ``seed``), over the preset's own
            (:data:`~kadv.models.marigold.PRESET_SETTINGS`); no other model takes any.

    Raises:
        ModelWeightsUnavailable: weights neither given, cached nor downloadable.
        FileNotFoundError: a path (starting with /, ./, ../ or ~) that is not a directory.
        MissingExtra: a Marigold preset without diffusers installed.
        ValueError: an empty name, an unknown model, or settings the model does not take.
    """
    name = str(name_or_path)
    if not name:
        raise ValueError("model name is empty")
    preset = PRESETS.get(name)
    if preset is not None and preset.family == "marigold":
        from kadv.models.marigold import MARIGOLD_SETTINGS, PRESET_SETTINGS, MarigoldSettings, load_marigold

        unknown = sorted(set(settings) - set(MARIGOLD_SETTINGS))
        if unknown:
            raise ValueError(f"model.{unknown[0]}: Marigold takes no such setting")
        settings = {**PRESET_SETTINGS.get(name, {}), **settings}
        return load_marigold(str(weights or preset.hub_id), name, preset.hub_id, MarigoldSettings(**settings))
    if settings:
        raise ValueError(
            f"model.{sorted(settings)[0]}: model {name!r} takes no such setting (only Marigold presets do)"
        )
    if name in ("kadv_tiny", "kadv_tiny_metric"):
        return load_kadv_tiny(weights, "disparity" if name == "kadv_tiny" else "depth")
    # transformers takes seconds to import; commands that load no Hugging Face model skip it
    from kadv.models.huggingface import load_huggingface
    from kadv.models.tiny_dpt import load_kadv_tiny_dpt

    if name == "kadv_tiny_dpt":
        return load_kadv_tiny_dpt(weights)
    if weights is not None:
        return load_huggingface(str(weights), name=name, hub_id=PRESETS[name].hub_id if name in PRESETS else name)
    if Path(name).expanduser().is_dir():
        return load_huggingface(name, name=Path(name).name)
    if name.startswith(("/", "./", "../", "~")):
        raise FileNotFoundError(f"no such model directory: {name}")
    if name in PRESETS:
        return load_huggingface(PRESETS[name].hub_id, name=name, hub_id=PRESETS[name].hub_id)
    if "/" not in name:
        raise ValueError(
            f"unknown model {name!r}: not a preset ({', '.join(sorted(PRESETS))}, kadv_tiny, kadv_tiny_metric, "
            "kadv_tiny_dpt), "
            "not a local directory, and not a Hugging Face id (owner/name)"
        )
    return load_huggingface(name, name=name, hub_id=name)
