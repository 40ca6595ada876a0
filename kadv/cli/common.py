"""Turning config nodes into library objects, and reporting a user's mistakes in one line.

This is the edge where Hydra meets the library; nothing under ``kadv/`` but ``cli/`` imports Hydra.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import json
import logging
import math
import os
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from hydra.core.hydra_config import HydraConfig
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from kadv.errors import WeightsUnavailable
from kadv.geometry import look_at
from kadv.io import write_json
from kadv.models import EMBEDDED, PRESETS, DepthModel, load_custom, load_model
from kadv.render import Shading
from kadv.scenes import Scene, box_room, load_scene, procedural_room

__all__ = [
    "FAILURE",
    "camera_from_config",
    "check_render_config",
    "checks_group_options",
    "dirname",
    "model_from_config",
    "reports_user_errors",
    "scene_from_config",
    "settings_from_node",
    "shading_from_config",
]

# A user's mistake (a bad value, a missing file, unavailable weights) is reported in one line;
# anything else is a bug and keeps its traceback.
USER_ERRORS = (ValueError, FileNotFoundError, NotADirectoryError, WeightsUnavailable, OmegaConfBaseException)


FAILURE = "failure.json"


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split()) or type(error).__name__


def reports_user_errors(command: str) -> Callable[[Callable[[DictConfig], Any]], Callable[[DictConfig], Any]]:
    """Decorate a Hydra task so that a user error prints ``<command>: error: <message>`` and exits 2.

    In a multirun, a failing job must not stop the others: any error is logged with its traceback,
    written to the job's ``failure.json`` (the sweep's callback gathers them into ``failures.json``)
    and the job returns. ``HYDRA_FULL_ERROR=1`` re-raises errors with their traceback.
    """

    def decorate(task: Callable[[DictConfig], Any]) -> Callable[[DictConfig], Any]:
        @functools.wraps(task)
        def wrapped(cfg: DictConfig) -> Any:
            hydra_config = HydraConfig.get()
            multirun = hydra_config.mode == RunMode.MULTIRUN
            failure = Path(hydra_config.runtime.output_dir) / FAILURE
            failure.unlink(missing_ok=True)
            try:
                return task(cfg)
            except Exception as error:
                if os.environ.get("HYDRA_FULL_ERROR") == "1" or not (multirun or isinstance(error, USER_ERRORS)):
                    raise
                message = f"{command}: error: {_one_line(error)}"
                print(message, file=sys.stderr)
                if not multirun:
                    sys.exit(2)
                logging.getLogger(command).error("job failed", exc_info=error)
                write_json(
                    failure,
                    {"job": hydra_config.job.num, "overrides": list(hydra_config.overrides.task), "error": message},
                )
                return None

        return wrapped

    return decorate


def checks_group_options(command: str) -> Callable[[Callable[[], Any]], Callable[[], Any]]:
    """Decorate a ``hydra.main`` entry point so that ``group=option`` naming no ``conf/group/option.yaml``
    (``model=no_such_preset``) prints ``<command>: error: ...`` in one line and exits 2, before
    Hydra's composition would fail with a multi-line message."""

    def decorate(entry: Callable[[], Any]) -> Callable[[], Any]:
        @functools.wraps(entry)
        def wrapped() -> Any:
            conf = importlib.resources.files("kadv.conf")
            for argument in sys.argv[1:]:
                group, equals, options = argument.partition("=")
                if not equals or not re.fullmatch(r"[a-z_]+", group) or not conf.joinpath(group).is_dir():
                    continue
                known = sorted(
                    p.name.removesuffix(".yaml") for p in conf.joinpath(group).iterdir() if p.name.endswith(".yaml")
                )
                for option in options.split(","):
                    if re.fullmatch(r"[A-Za-z0-9_]+", option) and option not in known:
                        listing = " (kadv-models lists the model presets)" if group == "model" else ""
                        print(
                            f"{command}: error: {group}={option}: no such option in {group}/; one of: "
                            f"{', '.join(known)}{listing}",
                            file=sys.stderr,
                        )
                        sys.exit(2)
            return entry()

        return wrapped

    return decorate


def dirname(overrides: str) -> str:
    """A folder name from Hydra's ``override_dirname``: "default" when empty, path separators and
    other unsafe characters replaced, so the same overrides always give the same folder."""
    name = re.sub(r"[^A-Za-z0-9._=,+-]", "_", overrides)
    return name[:200] or "default"


OmegaConf.register_new_resolver("kadv_dirname", dirname, replace=True)


def scene_from_config(cfg: DictConfig) -> Scene:
    """Build the scene a ``scene/`` config node describes (``kind``: box_room, procedural or file)."""
    if cfg.kind == "box_room":
        return box_room(seed=int(cfg.seed), num_boxes=int(cfg.num_boxes))
    if cfg.kind == "procedural":
        return procedural_room(seed=int(cfg.seed))
    if cfg.kind == "file":
        options = OmegaConf.to_container(cfg.get("options") or {}, resolve=True)
        return load_scene(Path(cfg.path).expanduser(), **options)
    raise ValueError(f"scene.kind must be 'box_room', 'procedural' or 'file', got {cfg.kind!r}")


def shading_from_config(cfg: DictConfig) -> Shading:
    lights = cfg.get("lights")
    return Shading(
        ambient=float(cfg.ambient),
        diffuse=float(cfg.diffuse),
        lights=None if lights is None else tuple(tuple(float(v) for v in light) for light in lights),
        background=tuple(float(v) for v in cfg.background),
    )


def check_render_config(cfg: DictConfig) -> tuple[int, int, int]:
    """(height, width, supersample) of a ``render/`` node, each checked to be a positive integer."""
    values = []
    for key in ("height", "width", "supersample"):
        value = cfg[key]
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"render.{key} must be a positive integer, got {value!r}")
        values.append(value)
    return tuple(values)


def _vector(cfg: DictConfig, key: str) -> torch.Tensor:
    value = cfg[key]
    try:
        numbers = [float(v) for v in value]
    except (TypeError, ValueError):
        numbers = []
    if len(numbers) != 3 or not all(math.isfinite(v) for v in numbers):
        # a missing key is null, which OmegaConf cannot print as YAML
        shown = OmegaConf.to_container(value) if OmegaConf.is_config(value) else value
        raise ValueError(f"camera.{key} must be three finite numbers [x, y, z], got {json.dumps(shown, default=str)}")
    return torch.tensor(numbers, dtype=torch.float64)


def camera_from_config(cfg: DictConfig, scene: Scene) -> tuple[torch.Tensor, float]:
    """(world_T_cam (4, 4), fov_x_deg) from an explicit pose, a look-at, or a file camera index."""
    fov = cfg.get("fov_x_deg")
    if cfg.get("world_T_cam") is not None:
        pose = torch.tensor(OmegaConf.to_container(cfg.world_T_cam), dtype=torch.float64)
    elif cfg.get("eye") is not None:
        pose = look_at(_vector(cfg, "eye"), _vector(cfg, "target"), _vector(cfg, "up"))
    else:
        if not scene.cameras:
            raise ValueError(f"scene {scene.name!r} defines no camera: give camera.world_T_cam or camera.eye/target")
        index = int(cfg.index)
        if not 0 <= index < len(scene.cameras):
            raise ValueError(f"camera.index={index} but scene {scene.name!r} has {len(scene.cameras)} camera(s)")
        camera = scene.cameras[index]
        return camera.world_T_cam, float(fov if fov is not None else camera.fov_x_deg)
    if fov is None:
        raise ValueError("camera.fov_x_deg is required with an explicit pose")
    return pose, float(fov)


def settings_from_node(cls: type, node: dict | None, prefix: str) -> Any:
    """The settings dataclass ``cls`` from a config node (a dict; None: the defaults); a key it does
    not know is an error naming ``<prefix>.<key>``. Lists become tuples."""
    node = dict(node or {})
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(node) - known)
    if unknown:
        raise ValueError(
            f"unknown key(s) {', '.join(f'{prefix}.{k}' for k in unknown)}; "
            f"{prefix} takes {', '.join(sorted(known)) or 'no keys'}"
        )
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in node.items()})


def model_from_config(node: Any) -> DepthModel:
    """The ``model`` node's model: ``model=custom`` instantiates ``model.target(**model.args)``
    with its declared ``model.output_kind``; any other preset loads by name (and ``model.weights``)."""
    node = OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else dict(node)
    if node.get("name") == "custom":
        return load_custom(node.get("target") or "", node.get("output_kind", "disparity"), node.get("args"))
    preset = EMBEDDED.get(node["name"]) or PRESETS.get(node["name"])
    for key in ("hub_id", "output_kind"):
        if preset is not None and node.get(key) is not None and node[key] != getattr(preset, key):
            raise ValueError(
                f"model.{key}: the preset {node['name']!r} has {key} {getattr(preset, key)!r}, fixed by its "
                f"checkpoint, not {node[key]!r}; for other weights use model=huggingface model.name=<id or dir>"
            )
    return load_model(node["name"], node.get("weights"))
