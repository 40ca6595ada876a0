"""Adapters for every ``transformers`` depth family: DPT (MiDaS, BEiT, DINOv2 heads), Depth
Anything v1/v2 (relative and metric), ZoeDepth, GLPN, DepthPro and TIPSv2-DPT.

Each family gets its output kind from its config and its image processor's steps as a
:class:`Preprocess` (read from the checkpoint's ``preprocessor_config.json`` over the family's
defaults). Weights resolve from an explicit path, then the Hugging Face cache, then the hub.
"""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar
from urllib.parse import urlparse

import torch
from transformers import AutoConfig, AutoModelForDepthEstimation
from transformers.utils import cached_file

from kadv.errors import WeightsUnavailable
from kadv.models.base import DepthModel
from kadv.models.preprocess import Preprocess

__all__ = [
    "FAMILY_DEFAULTS",
    "METRIC_FAMILIES",
    "REFUSED_FAMILIES",
    "DepthProDepthModel",
    "HuggingFaceDepthModel",
    "ModelWeightsUnavailable",
    "family_preprocess",
    "hub_offline",
    "load_huggingface",
    "output_kind",
    "resolve_weights",
]

T = TypeVar("T")

_HALF = (0.5, 0.5, 0.5)
# What each family's image processor does when a checkpoint carries no preprocessor_config.json
# (the class defaults of its transformers processor; Depth Anything's are its checkpoints' own).
# The PIL-backend processors (DPT, Depth Anything, GLPN) resample as PIL does, hence antialias.
FAMILY_DEFAULTS = {
    "dpt": Preprocess(size=(384, 384), mean=_HALF, std=_HALF, antialias=True, output_interpolation="bicubic"),
    "depth_anything": Preprocess(
        size=(518, 518), keep_aspect_ratio=True, multiple=14, antialias=True, output_interpolation="bicubic"
    ),
    "zoedepth": Preprocess(
        size=(384, 512),
        keep_aspect_ratio=True,
        multiple=32,
        reflect_pad=True,
        mean=_HALF,
        std=_HALF,
        interpolation="bilinear",
        align_corners=True,
        output_interpolation="bicubic",
    ),
    "glpn": Preprocess(
        size=None,
        floor_multiple=32,
        mean=None,
        std=None,
        interpolation="bilinear",
        antialias=True,
        output_interpolation="bicubic",
    ),
    "depth_pro": Preprocess(size=(1536, 1536), mean=_HALF, std=_HALF, normalize_first=True, interpolation="bilinear"),
    "tipsv2_dpt": Preprocess(size=(448, 448), mean=None, std=None, interpolation="bilinear", antialias=True),
}
# PIL resampling codes in preprocessor_config.json
_RESAMPLE = {0: "nearest", 2: "bilinear", 3: "bicubic"}


class ModelWeightsUnavailable(WeightsUnavailable):
    """The weights of a model cannot be found locally and cannot be downloaded."""


def hub_offline() -> bool:
    return any(
        os.environ.get(k, "").lower() in ("1", "true", "yes", "on") for k in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE")
    )


def hub_reachable(timeout: float = 3.0) -> bool:
    """Whether the hub's host answers a TCP connection within ``timeout`` seconds.

    Asked once before a download, so that a machine without network fails in seconds instead of
    waiting out the hub client's retries (about half a minute).
    """
    host = urlparse(os.environ.get("HF_ENDPOINT", "https://huggingface.co")).hostname or "huggingface.co"
    try:
        socket.create_connection((host, 443), timeout=timeout).close()
    except OSError:
        return False
    return True


def _processor_config(source: str, local_only: bool) -> dict[str, Any] | None:
    file = cached_file(
        source,
        "preprocessor_config.json",
        local_files_only=local_only,
        _raise_exceptions_for_missing_entries=False,
        _raise_exceptions_for_connection_errors=False,
    )
    return None if file is None else json.loads(Path(file).read_text())


def family_preprocess(config: Any, processor: dict[str, Any] | None = None) -> Preprocess:
    """The :class:`Preprocess` of a transformers depth model: its family's processor defaults,
    overridden by what its ``preprocessor_config.json`` (``processor``) sets.

    Raises:
        ValueError: a resampling filter kadv cannot reproduce differentiably.
    """
    family = config.model_type
    base = FAMILY_DEFAULTS[family]
    if family == "depth_pro":  # the network's fixed square input: its patch size over the smallest scale
        side = round(config.patch_size / min(config.scaled_images_ratios))
        base = replace(base, size=(side, side))
    if not processor:
        return base
    changes: dict[str, Any] = {}
    size = processor.get("size")
    if isinstance(size, int):
        size = {"height": size, "width": size}
    if isinstance(size, dict) and "height" in size and family != "glpn":
        changes["size"] = (int(size["height"]), int(size["width"]))
    if processor.get("do_resize", True) is False:
        changes["size"] = None
    for key, field in (("keep_aspect_ratio", "keep_aspect_ratio"), ("ensure_multiple_of", "multiple")):
        if key in processor:
            changes[field] = type(getattr(base, field))(processor[key])
    if family == "glpn":
        changes["floor_multiple"] = int(processor.get("size_divisor", base.floor_multiple))
    elif family == "zoedepth":
        changes["reflect_pad"] = bool(processor.get("do_pad", base.reflect_pad))
    elif processor.get("do_pad") and processor.get("size_divisor"):
        changes["pad_multiple"] = int(processor["size_divisor"])
    normalise = processor.get("do_normalize", base.mean is not None)
    changes["mean"] = tuple(processor.get("image_mean", base.mean or (0.0,) * 3)) if normalise else None
    changes["std"] = tuple(processor.get("image_std", base.std or (1.0,) * 3)) if normalise else None
    if "resample" in processor:
        if processor["resample"] not in _RESAMPLE:
            raise ValueError(
                f"preprocessor_config.json: resample={processor['resample']} cannot be reproduced "
                f"differentiably (supported: {sorted(_RESAMPLE)}, PIL's nearest, bilinear, bicubic)"
            )
        changes["interpolation"] = _RESAMPLE[processor["resample"]]
    return replace(base, **changes)


class HuggingFaceDepthModel(DepthModel):
    """A ``transformers`` depth-estimation model behind the :class:`DepthModel` interface."""

    def __init__(self, network: torch.nn.Module, preprocess: Preprocess, output_kind: str, name: str) -> None:
        super().__init__(preprocess, output_kind, name)
        self.network = network
        self.freeze()

    def predict(self, pixel_values: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        return self.network(pixel_values=pixel_values).predicted_depth


class DepthProDepthModel(HuggingFaceDepthModel):
    """DepthPro: its head predicts a canonical inverse depth that becomes metric depth through
    the focal length, depth = f / (W * inverse), with f in pixels at the image width W.

    Given intrinsics K, f is the true focal length fx, so the metric scale is the scene's; without
    K it comes from the field of view the network predicts (as its processor's post-processing
    does), and without that the canonical inverse depth is inverted as it is. ``model.intrinsics=
    withheld`` leaves K out, so that its own field of view sets the scale.
    """

    takes_K = True

    def forward(self, rgb: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        width = rgb.shape[-1]
        x = rgb.to(next(self.parameters()).device)
        K = self.camera(K)
        pixel_values, layout = self.preprocess.to_network(x)
        output = self.network(pixel_values=pixel_values)
        inverse = self.preprocess.from_network(self._as_map(output.predicted_depth), layout)
        if K is not None:
            focal = K.to(inverse).reshape(-1, 3, 3)[:, 0, 0]
        elif output.field_of_view is not None:
            focal = 0.5 * width / torch.tan(0.5 * torch.deg2rad(output.field_of_view.reshape(-1)))
        else:
            focal = torch.full((1,), float(width), dtype=inverse.dtype, device=inverse.device)
        # the bounds of DepthPro's own post-processing
        depth = 1.0 / (inverse * width / focal.reshape(-1, 1, 1, 1)).clamp(1e-4, 1e4)
        return depth.to(rgb.device)


# transformers depth families whose head predicts metric depth (the others: relative inverse depth)
METRIC_FAMILIES = frozenset({"depth_pro", "glpn", "tipsv2_dpt", "zoedepth"})
# families that are not single-image scene-depth estimators kadv can attack as they are, and why
REFUSED_FAMILIES = {
    "chmv2": "CHMv2 is a canopy-height model for aerial images (height above ground), not scene depth from one view",
    "prompt_depth_anything": "Prompt Depth Anything needs a prompt depth map (e.g. LiDAR) beside the image, "
    "which kadv does not supply",
}


def output_kind(config: Any) -> str:
    """What a transformers depth model's prediction holds: "depth" (metres) or "disparity".

    Depth Anything declares it in ``depth_estimation_type``; DPT heads on a DINOv2 backbone
    (``facebook/dpt-dinov2-*-nyu``/``-kitti``) were trained on metric depth, the other DPTs
    (MiDaS, BEiT, hybrid) on relative inverse depth.

    Raises:
        ValueError: a family kadv refuses (see ``REFUSED_FAMILIES``) or does not know.
    """
    family = config.model_type
    if family in REFUSED_FAMILIES:
        raise ValueError(f"model family {family!r} is not supported: {REFUSED_FAMILIES[family]}")
    if family not in FAMILY_DEFAULTS:
        raise ValueError(
            f"model family {family!r} is not one kadv knows ({', '.join(sorted(FAMILY_DEFAULTS))}); "
            "wrap it with kadv.models.wrap_model and declare its output kind"
        )
    backbone = getattr(getattr(config, "backbone_config", None), "model_type", None)
    if (
        family in METRIC_FAMILIES
        or getattr(config, "depth_estimation_type", "relative") == "metric"
        or (family == "dpt" and backbone == "dinov2")
    ):
        return "depth"
    return "disparity"


def load_huggingface(source: str, name: str | None = None, hub_id: str | None = None) -> HuggingFaceDepthModel:
    """Load a depth model from a local ``save_pretrained`` directory or a hub id.

    Args:
        source: a directory, or a hub id looked up in the cache first and the hub second.
        name: label for reports (defaults to ``source``).
        hub_id: the hub id behind a preset, for the error message.

    Raises:
        ModelWeightsUnavailable: not cached and offline (or the download failed), with how to fix it.
    """

    def load(location: str, local_only: bool) -> HuggingFaceDepthModel:
        config = AutoConfig.from_pretrained(location, local_files_only=local_only)
        kind = output_kind(config)
        preprocess = family_preprocess(config, _processor_config(location, local_only))
        network = AutoModelForDepthEstimation.from_pretrained(location, local_files_only=local_only)
        adapter = DepthProDepthModel if config.model_type == "depth_pro" else HuggingFaceDepthModel
        return adapter(network, preprocess, kind, name or source)

    return resolve_weights(source, load, name, hub_id)


def resolve_weights(
    source: str, load: Callable[[str, bool], T], name: str | None = None, hub_id: str | None = None
) -> T:
    """``load(location, local_only)`` from a local directory, else the Hugging Face cache, else the
    hub (unless offline or unreachable); ``load`` raises an ``OSError`` where the files are missing.

    Raises:
        ModelWeightsUnavailable: one message naming where kadv looked and how to provide the weights.
    """
    name = name or source
    local_dir = Path(source).expanduser()
    location = str(local_dir) if local_dir.is_dir() else source
    attempts = [True] if local_dir.is_dir() or hub_offline() else [True, False]
    unreachable = False
    last_error: Exception | None = None
    for local_only in attempts:
        if not local_only and not hub_reachable():
            unreachable = True
            break
        try:
            return load(location, local_only)
        except OSError as error:
            last_error = error
    where = f"the directory {local_dir}" if local_dir.is_dir() else f"the Hugging Face cache ({hub_id or source})"
    reason = (
        "the hub is offline (HF_HUB_OFFLINE=1)"
        if hub_offline()
        else "the hub cannot be reached from here"
        if unreachable
        else "the download failed"
    )
    raise ModelWeightsUnavailable(
        f"model {name!r}: weights not found in {where} and {reason}. Provide them by passing a local "
        f"directory in save_pretrained layout (load_model('/path/to/dir') or model.weights=/path/to/dir), or download "
        f"'{hub_id or source}' into the Hugging Face cache on a machine with internet (huggingface-cli download "
        f"{hub_id or source}) and copy the cache (HF_HOME) here."
    ) from last_error
