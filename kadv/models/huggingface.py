"""Adapters for ``transformers`` depth models (DPT, DPT-hybrid, ZoeDepth, Depth Anything v1/v2, ...).

Weights resolve from an explicit path, then the Hugging Face cache, then the hub.
"""
from __future__ import annotations

import json
import os
import socket
from pathlib import Path
from urllib.parse import urlparse

import torch
from transformers import AutoConfig, AutoModelForDepthEstimation
from transformers.utils import cached_file

from kadv.errors import WeightsUnavailable
from kadv.models.base import DepthModel, Preprocess

__all__ = ["METRIC_FAMILIES", "REFUSED_FAMILIES", "HuggingFaceDepthModel", "ModelWeightsUnavailable", "hub_offline",
           "load_huggingface", "output_kind"]

# Per architecture, what the original image processors do when a checkpoint carries no
# preprocessor_config.json (e.g. a config saved with save_pretrained alone).
_DEFAULTS = {
    "dpt": Preprocess(size=(384, 384), keep_aspect_ratio=False, multiple=1, mean=(0.5,) * 3, std=(0.5,) * 3),
    "zoedepth": Preprocess(size=(384, 512), keep_aspect_ratio=True, multiple=32, mean=(0.5,) * 3, std=(0.5,) * 3),
    "depth_anything": Preprocess(size=(518, 518), keep_aspect_ratio=True, multiple=14),
}


class ModelWeightsUnavailable(WeightsUnavailable):
    """The weights of a model cannot be found locally and cannot be downloaded."""


def hub_offline() -> bool:
    return any(os.environ.get(k, "").lower() in ("1", "true", "yes", "on") for k in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE"))


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


def _preprocess(source: str, model_type: str, local_only: bool) -> Preprocess:
    default = _DEFAULTS.get(model_type, _DEFAULTS["depth_anything"])
    file = cached_file(source, "preprocessor_config.json", local_files_only=local_only,
                       _raise_exceptions_for_missing_entries=False, _raise_exceptions_for_connection_errors=False)
    if file is None:
        return default
    config = json.loads(Path(file).read_text())
    size = config.get("size", {})
    if isinstance(size, int):
        size = {"height": size, "width": size}
    return Preprocess(
        size=(int(size.get("height", default.size[0])), int(size.get("width", default.size[1]))),
        keep_aspect_ratio=bool(config.get("keep_aspect_ratio", default.keep_aspect_ratio)),
        multiple=int(config.get("ensure_multiple_of", default.multiple)),
        mean=tuple(config.get("image_mean", default.mean)) if config.get("do_normalize", True) else (0.0,) * 3,
        std=tuple(config.get("image_std", default.std)) if config.get("do_normalize", True) else (1.0,) * 3,
    )


class HuggingFaceDepthModel(DepthModel):
    """A ``transformers`` depth-estimation model behind the :class:`DepthModel` interface."""

    def __init__(self, network: torch.nn.Module, preprocess: Preprocess, output_kind: str, name: str) -> None:
        super().__init__(preprocess, output_kind, name)
        self.network = network
        self.freeze()

    def predict(self, pixel_values: torch.Tensor) -> torch.Tensor:
        return self.network(pixel_values=pixel_values).predicted_depth


# transformers depth families whose head predicts metric depth (the others: relative inverse depth)
METRIC_FAMILIES = frozenset({"glpn", "tipsv2_dpt", "zoedepth"})
# families that are not single-image scene-depth estimators kadv can attack as they are, and why
REFUSED_FAMILIES = {
    "chmv2": "CHMv2 is a canopy-height model for aerial images (height above ground), not scene depth from one view",
    "prompt_depth_anything": "Prompt Depth Anything needs a prompt depth map (e.g. LiDAR) beside the image, "
                             "which kadv does not supply",
}


def output_kind(config: object) -> str:
    """What a transformers depth model's ``predicted_depth`` holds: "depth" (metres) or "disparity".

    Depth Anything declares it in ``depth_estimation_type``; DepthPro's raw output is a canonical
    inverse depth, so it is compared as disparity (alignment supplies its scale).

    Raises:
        ValueError: a family kadv refuses (see ``REFUSED_FAMILIES``).
    """
    family = config.model_type
    if family in REFUSED_FAMILIES:
        raise ValueError(f"model family {family!r} is not supported: {REFUSED_FAMILIES[family]}")
    if family in METRIC_FAMILIES or getattr(config, "depth_estimation_type", "relative") == "metric":
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
            config = AutoConfig.from_pretrained(location, local_files_only=local_only)
            kind = output_kind(config)
            network = AutoModelForDepthEstimation.from_pretrained(location, local_files_only=local_only)
            preprocess = _preprocess(location, config.model_type, local_only)
            return HuggingFaceDepthModel(network, preprocess, kind, name)
        except OSError as error:
            last_error = error
    where = f"the directory {local_dir}" if local_dir.is_dir() else f"the Hugging Face cache ({hub_id or source})"
    reason = ("the hub is offline (HF_HUB_OFFLINE=1)" if hub_offline()
              else "the hub cannot be reached from here" if unreachable else "the download failed")
    raise ModelWeightsUnavailable(
        f"model {name!r}: weights not found in {where} and {reason}. Provide them by passing a local "
        f"directory in save_pretrained layout (load_model('/path/to/dir') or model.weights=/path/to/dir), or download "
        f"'{hub_id or source}' into the Hugging Face cache on a machine with internet (huggingface-cli download "
        f"{hub_id or source}) and copy the cache (HF_HOME) here."
    ) from last_error
