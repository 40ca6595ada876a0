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
import shutil
import sys
import tempfile
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra import compose, initialize_config_module
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException, OverrideParseException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import ConfigAttributeError, ConfigKeyError, OmegaConfBaseException

from kadv.attack import RENAMED_BUDGET, StudySettings
from kadv.catalogue import scene_from_node
from kadv.errors import MissingExtra, WeightsUnavailable, WriteError
from kadv.geometry import look_at
from kadv.io import write_json
from kadv.losses import DELTA1_TEMPERATURE, LossConfig
from kadv.models import EMBEDDED, PRESETS, DepthModel, check_intrinsics, load_custom, load_model
from kadv.render import BakeConfig, DiffRenderConfig, Shading
from kadv.render.exact import DEFAULT_MAX_RAYS
from kadv.report.store import LOCK_FILES, RunDirectoryBusy
from kadv.scenes import Scene
from kadv.scenes.procedural import CORRIDOR_SHARE, HALL_SHARE, ROOM_FEATURES, check_shares

__all__ = [
    "FAILURE",
    "camera_from_config",
    "check_render_config",
    "checks_overrides",
    "config_float",
    "config_int",
    "dirname",
    "loss_settings",
    "model_from_config",
    "reports_user_errors",
    "resolve_lighting",
    "scene_from_config",
    "settings_from_node",
    "shading_from_config",
    "study_settings",
]

# A user's mistake (a bad value, a missing file, unavailable weights, a run directory another run
# holds) is reported in one line with exit status 2, a fault of the environment (a file that
# cannot be written) in one line with status 1; anything else is a bug and keeps its traceback.
USER_ERRORS = (
    ValueError,
    FileNotFoundError,
    NotADirectoryError,
    WeightsUnavailable,
    MissingExtra,
    OmegaConfBaseException,
    RunDirectoryBusy,
)
ENVIRONMENT_ERRORS = (WriteError,)
log = logging.getLogger(__name__)


FAILURE = "failure.json"


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split()) or type(error).__name__


def reports_user_errors(command: str) -> Callable[[Callable[[DictConfig], Any]], Callable[[DictConfig], Any]]:
    """Decorate a Hydra task so that a user error prints ``<command>: error: <message>`` and exits 2,
    and a file it cannot write (a full disk, a read-only folder) prints the same and exits 1.

    In a multirun, a failing job must not stop the others: any error is logged with its traceback,
    written to the job's ``failure.json`` (the sweep's callback gathers them into ``failures.json``)
    and the job returns. ``HYDRA_FULL_ERROR=1`` re-raises errors with their traceback.
    """

    def decorate(task: Callable[[DictConfig], Any]) -> Callable[[DictConfig], Any]:
        @functools.wraps(task)
        def wrapped(cfg: DictConfig) -> Any:
            hydra_config = HydraConfig.get()
            multirun = hydra_config.mode == RunMode.MULTIRUN
            run_dir = Path(hydra_config.runtime.output_dir)
            failure = run_dir / FAILURE
            failure.unlink(missing_ok=True)
            before = {p.name for p in run_dir.iterdir()} if run_dir.is_dir() else set()
            try:
                return task(cfg)
            except Exception as error:
                known = isinstance(error, USER_ERRORS + ENVIRONMENT_ERRORS)
                if os.environ.get("HYDRA_FULL_ERROR") == "1" or not (multirun or known):
                    raise
                message = f"{command}: error: {_one_line(error)}"
                print(message, file=sys.stderr)
                if not multirun:
                    if isinstance(error, USER_ERRORS):
                        _discard_written(run_dir, before)
                    sys.exit(1 if isinstance(error, ENVIRONMENT_ERRORS) else 2)
                logging.getLogger(command).error("job failed", exc_info=error)
                write_json(
                    failure,
                    {"job": hydra_config.job.num, "overrides": list(hydra_config.overrides.task), "error": message},
                )
                return None

        return wrapped

    return decorate


# what a run directory holds once Hydra has started a job in it, before the task writes anything
_STARTED = (".hydra", *LOCK_FILES)


def _discard_written(run_dir: Path, before: set[str]) -> None:
    """Undo what a job refused for its input wrote in ``run_dir``: the entries it added since
    ``before`` (the names there when the task began), and the directory itself if what is left is
    only what starting the job put there (Hydra's ``.hydra`` and log, the run lock). A run that
    was there before (one to resume, a user's files) keeps everything it had."""
    if not run_dir.is_dir():
        return
    for path in run_dir.iterdir():
        if path.name in before:
            continue
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
    if all(p.name in _STARTED or p.suffix == ".log" for p in run_dir.iterdir()):
        shutil.rmtree(run_dir, ignore_errors=True)


def _unknown_group_option(command: str, arguments: list[str]) -> str | None:
    """The message for the first ``group=option`` naming no ``conf/group/option.yaml``, else None."""
    conf = importlib.resources.files("kadv.conf")
    for argument in arguments:
        group, equals, options = argument.partition("=")
        if not equals or not re.fullmatch(r"[a-z_]+", group) or not conf.joinpath(group).is_dir():
            continue
        known = sorted(p.name.removesuffix(".yaml") for p in conf.joinpath(group).iterdir() if p.name.endswith(".yaml"))
        for option in options.split(","):
            if re.fullmatch(r"[A-Za-z0-9_]+", option) and option not in known:
                listing = " (kadv-models lists the model presets)" if group == "model" else ""
                return f"{group}={option}: no such option in {group}/; one of: {', '.join(known)}{listing}"
    return None


def _composition_error(config_name: str, arguments: list[str]) -> str | None:
    """Why Hydra cannot compose ``config_name`` with the override ``arguments`` (a sweep's first
    value standing for the sweep), in one line; None when it can, or when only the sweeper could
    tell (``glob(...)``)."""
    try:
        overrides = OverridesParser.create().parse_overrides(arguments)
    except OverrideParseException as error:
        return f"cannot parse the overrides: {str(error).splitlines()[0]}"
    firsts = []
    for override in overrides:
        if not override.is_sweep_override():
            firsts.append(override.input_line)
            continue
        try:
            first = next(iter(override.sweep_string_iterator()))
        except HydraException:
            return None
        firsts.append(f"{override.input_line.partition('=')[0]}={first}")
    try:
        _compose(config_name, firsts)
    except (HydraException, OmegaConfBaseException) as error:
        cause = error.__cause__
        message = str(error).splitlines()[0].rstrip(".")
        if isinstance(cause, (ConfigKeyError, ConfigAttributeError)) and cause.full_key:
            parent, _, key = cause.full_key.rpartition(".")
            return f"{message}: {parent or 'the config'} has no key {key!r}" + _keys_of(config_name, firsts, parent)
        return _one_line(f"{message} {cause or ''}")
    for override in overrides:
        parent, _, key = override.key_or_group.rpartition(".")
        # "+node.key=value" adds a key Hydra would otherwise refuse; in kadv's own nodes no code reads
        # it, so it is refused as a misspelt key is (Hydra's nodes and the open ones take any key)
        if override.is_add() and parent and not parent.startswith("hydra") and parent not in OPEN_NODES:
            others = [f for f in firsts if f.lstrip("+~").partition("=")[0] != override.key_or_group]
            found = OmegaConf.select(_compose(config_name, others), override.key_or_group)
            if found is None:
                return f"{override.input_line}: {parent} has no key {key!r}" + _keys_of(config_name, firsts, parent)
    return None


def _keys_of(config_name: str, overrides: list[str], node: str) -> str:
    """A suffix listing ``node``'s keys, composed without the overrides under ``node``; empty if there is none."""
    if not node:
        return ""
    try:
        found = OmegaConf.select(
            _compose(config_name, [o for o in overrides if not o.lstrip("+~").startswith(f"{node}.")]), node
        )
    except (HydraException, OmegaConfBaseException):
        return ""
    return f"; it has: {', '.join(map(str, found.keys()))}" if isinstance(found, DictConfig) else ""


def _compose(config_name: str, overrides: list[str]) -> DictConfig:
    with initialize_config_module("kadv.conf", version_base="1.3"):
        return compose(config_name, overrides)


# Hydra's own flags; with any other (--cfg, --config-name, --help, ...) Hydra composes as it likes.
_RUN_FLAGS = {"-m", "--multirun", "-r", "--run"}
# nodes whose keys are the user's own (a custom model's keyword arguments): set without Hydra's "+"
OPEN_NODES = ("model.args",)


def _open_keys(arguments: list[str]) -> list[str]:
    """``arguments`` with ``node.key=value`` under an open node written ``++node.key=value`` (add or
    set), so that a user's keyword argument needs no "+"."""
    return [f"++{a}" if any(a.startswith(f"{node}.") for node in OPEN_NODES) else a for a in arguments]


# config keys renamed: old dotted key -> the line that refuses it, naming the new one
RENAMED_KEYS = {
    "attack.budget_evaluations": RENAMED_BUDGET,
    "penalty.probe_rays": "penalty.probe_rays was renamed penalty.enclosure_rays: the rays around a camera's "
    "centre that tell whether it stands inside an object or outside the scene",
}


def _renamed_key(arguments: list[str]) -> str | None:
    """The line refusing a key that was renamed, naming the new one; None when no argument sets one."""
    keys = [a.lstrip("+~").partition("=")[0] for a in arguments]
    return next((RENAMED_KEYS[k] for k in keys if k in RENAMED_KEYS), None)


def checks_overrides(command: str) -> Callable[[Callable[[], Any]], Callable[[], Any]]:
    """Decorate a ``hydra.main`` entry point so that an override Hydra cannot apply (``model=no_such_preset``,
    a key the composed config lacks, a malformed value) prints ``<command>: error: ...`` in one line
    and exits 2, before Hydra's composition would fail with a multi-line message and exit 1.

    The config composed is the one named after the command (``kadv-attack``: ``kadv_attack.yaml``).
    """

    def decorate(entry: Callable[[], Any]) -> Callable[[], Any]:
        @functools.wraps(entry)
        def wrapped() -> Any:
            sys.argv[1:] = arguments = _open_keys(sys.argv[1:])
            message = _unknown_group_option(command, arguments) or _renamed_key(arguments)
            if message is None and all(a in _RUN_FLAGS or not a.startswith("-") for a in arguments):
                message = _composition_error(command.replace("-", "_"), [a for a in arguments if a not in _RUN_FLAGS])
            if message is not None:
                print(f"{command}: error: {message}", file=sys.stderr)
                sys.exit(2)
            if all(a in _RUN_FLAGS or not a.startswith("-") for a in arguments):
                # before Hydra, which makes the run directory and its log there and would fail with a traceback
                message = _unwritable(_output_root(command.replace("-", "_"), arguments))
                if message is not None:
                    print(f"{command}: error: {message}", file=sys.stderr)
                    sys.exit(1)
            return entry()

        return wrapped

    return decorate


def _output_root(config_name: str, arguments: list[str]) -> Path:
    """The folder a run (or, with ``-m``, a sweep) writes under, as far as it is known before Hydra
    runs: ``hydra.run.dir`` (``hydra.sweep.dir``), given or the config's, up to its first interpolation."""
    key = "hydra.sweep.dir" if any(a in ("-m", "--multirun") for a in arguments) else "hydra.run.dir"
    given = [a.partition("=")[2] for a in arguments if a.lstrip("+").partition("=")[0] == key]
    if given:
        folder = given[-1]
    else:
        with initialize_config_module("kadv.conf", version_base="1.3"):
            hydra_node = compose(config_name, return_hydra_config=True).hydra
        folder = OmegaConf.to_container(hydra_node, resolve=False)[key.split(".")[1]]["dir"]
    return Path(folder.split("${", 1)[0] or ".").absolute()


def _unwritable(folder: Path) -> str | None:
    """Why nothing can be written in ``folder`` (made if missing), in one line; None if it can."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        return str(WriteError(error.filename or folder, error))
    return None


def dirname(overrides: str) -> str:
    """A folder name from Hydra's ``override_dirname``: "default" when empty, path separators and
    other unsafe characters replaced, so the same overrides always give the same folder."""
    name = re.sub(r"[^A-Za-z0-9._=,+-]", "_", overrides)
    return name[:200] or "default"


OmegaConf.register_new_resolver("kadv_dirname", dirname, replace=True)


def config_int(value: Any, key: str, minimum: int | None = None) -> int:
    """``value`` of the config key ``key`` as an int; anything else (text, a float, a bool, below
    ``minimum``) is an error naming the key.

    >>> config_int("abc", "scene.seed")
    Traceback (most recent call last):
    ...
    ValueError: scene.seed must be an integer, got 'abc'
    """
    if isinstance(value, bool) or not isinstance(value, int) or (minimum is not None and value < minimum):
        bound = "" if minimum is None else f" >= {minimum}"
        raise ValueError(f"{key} must be an integer{bound}, got {value!r}")
    return value


def config_float(value: Any, key: str) -> float:
    """``value`` of the config key ``key`` as a finite float; anything else is an error naming the key."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, got {value!r}")
    return float(value)


def loss_settings(cfg: DictConfig) -> LossConfig:
    """The :class:`~kadv.losses.LossConfig` a ``loss/`` config node describes, its numbers checked
    (a run saved before ``loss.alignment`` existed aligns as the study did: scale and shift)."""
    return LossConfig(
        kind=cfg.kind,
        space=cfg.get("space", "disparity"),
        alignment=cfg.get("alignment", "scale_shift"),
        vgg_weights=cfg.get("vgg_weights"),
        window_size=config_int(cfg.get("window_size", 11), "loss.window_size", 1),
        temperature=config_float(cfg.get("temperature", DELTA1_TEMPERATURE), "loss.temperature"),
    )


def scene_from_config(cfg: DictConfig) -> Scene:
    """Build the scene a ``scene/`` config node describes (``kind``: box_room, procedural or file),
    its numbers checked first so that a wrong one is named."""
    if cfg.kind in ("box_room", "procedural", "probe"):
        config_int(cfg.seed, "scene.seed")
    if cfg.kind == "box_room":
        config_int(cfg.num_boxes, "scene.num_boxes", 0)
    if cfg.kind == "procedural":
        features = {name: config_float(cfg.get(name, 0.0), f"scene.{name}") for name in ROOM_FEATURES}
        check_shares(CORRIDOR_SHARE, HALL_SHARE, "scene.", **features)
    # reading cfg.path refuses a missing one (???) in OmegaConf's words, which name the key
    path = cfg.path if cfg.kind == "file" else None
    return scene_from_node(OmegaConf.to_container(cfg, resolve=True), path=path)


def shading_from_config(cfg: DictConfig) -> Shading:
    """The :class:`Shading` of a ``render/`` node: ``render.shading.*``, ``render.lighting`` and
    ``render.bake.*`` (a run saved before lighting existed renders with ``direct``)."""
    shading = cfg.shading
    lights = shading.get("lights")
    bake = OmegaConf.to_container(cfg.get("bake") or {}, resolve=True)
    return Shading(
        ambient=config_float(shading.ambient, "render.shading.ambient"),
        diffuse=config_float(shading.diffuse, "render.shading.diffuse"),
        lights=None if lights is None else tuple(tuple(float(v) for v in light) for light in lights),
        background=tuple(float(v) for v in shading.background),
        lighting=cfg.get("lighting", "direct"),
        bake=settings_from_node(BakeConfig, bake, "render.bake"),
        reflections=shading.get("reflections", False),
    )


def resolve_lighting(scene: Scene, cfg: DictConfig) -> str:
    """``render.lighting``, with ``auto`` made ``scanned`` for a recognised scan (its colour is the
    light its sensor captured) and ``baked`` for any other scene; written back into ``cfg`` (so that
    a run's ``config.yaml`` names it) and said in the log."""
    lighting = cfg.get("lighting", "direct")
    if lighting == "auto":
        lighting = "scanned" if scene.captured_by is not None else "baked"
        cfg.lighting = lighting
        reason = f"a {scene.captured_by} scan" if scene.captured_by is not None else "not a scan"
        log.info("render.lighting=auto: %s (%s)", lighting, reason)
    return lighting


def study_settings(scene: Scene, cfg: DictConfig, device: torch.device | str = "cpu", **fields: Any) -> StudySettings:
    """The :class:`~kadv.attack.StudySettings` of ``scene`` that a ``render/`` node describes: the
    size, the shading (``render.lighting=auto`` resolved in ``cfg``: :func:`resolve_lighting`), the
    ray caster (``render.backend``, on ``device``; a run saved before backends existed casts with
    auto), the most rays cast at once (``render.max_rays``) and the differentiable renderer's
    options, with the other ``fields`` given (loss, penalty, attack, progress)."""
    resolve_lighting(scene, cfg)
    height, width, supersample = check_render_config(cfg)
    differentiable = OmegaConf.to_container(cfg.get("differentiable") or {}, resolve=True)
    return StudySettings(
        size=(height, width),
        shading=shading_from_config(cfg),
        backend=cfg.get("backend", "auto"),
        max_rays=config_int(cfg.get("max_rays", DEFAULT_MAX_RAYS), "render.max_rays", 1),
        render=DiffRenderConfig(supersample=supersample, **differentiable),
        device=device,
        **fields,
    )


def check_render_config(cfg: DictConfig) -> tuple[int, int, int]:
    """(height, width, supersample) of a ``render/`` node, each checked to be a positive integer."""
    return tuple(config_int(cfg[key], f"render.{key}", 1) for key in ("height", "width", "supersample"))


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


def frame_note(scene: Scene) -> str | None:
    """One line saying which frame poses are in, when the scene file's coordinates are not kadv's
    world (a z-up scan, an alignment, ``up_axis=auto``, a scale); None when they are."""
    if np.allclose(scene.world_T_file, np.eye(4)):
        return None
    matrix = np.array2string(np.round(scene.world_T_file, 6), separator=", ").replace("\n", "")
    return (
        f"poses (camera.*, render.json, init_params.json) are in kadv's world, y up in metres; a point p "
        f"of {scene.name}'s file is world_T_file @ p there, world_T_file = {' '.join(matrix.split())} "
        "(kadv-render's camera.frame=file takes camera.* in the file's coordinates)"
    )


def camera_from_config(cfg: DictConfig, scene: Scene) -> tuple[torch.Tensor, float]:
    """(world_T_cam (4, 4), fov_x_deg) from an explicit pose, a look-at, or a file camera index;
    ``camera.frame=file`` takes the pose or look-at in the scene file's coordinates
    (:attr:`Scene.world_T_file` maps them)."""
    fov = cfg.get("fov_x_deg")
    frame = cfg.get("frame", "world")
    if frame not in ("world", "file"):
        raise ValueError(f"camera.frame must be world or file, got {frame!r}")
    to_world = torch.from_numpy(scene.world_T_file if frame == "file" else np.eye(4))
    turn = to_world[:3, :3] / torch.linalg.det(to_world[:3, :3]).abs() ** (1 / 3)  # the rotation, scale left out
    if cfg.get("world_T_cam") is not None:
        pose = torch.tensor(OmegaConf.to_container(cfg.world_T_cam), dtype=torch.float64)
        pose = torch.cat([torch.cat([turn @ pose[:3, :3], (to_world @ pose[:, 3])[:3, None]], dim=1), pose[3:]])
    elif cfg.get("eye") is not None:

        def point(key: str) -> torch.Tensor:
            return (to_world @ torch.cat([_vector(cfg, key), torch.ones(1, dtype=torch.float64)]))[:3]

        pose = look_at(point("eye"), point("target"), turn @ _vector(cfg, "up"))
    else:
        if not scene.cameras:
            raise ValueError(f"scene {scene.name!r} defines no camera: give camera.world_T_cam or camera.eye/target")
        index = config_int(cfg.index, "camera.index")
        if not 0 <= index < len(scene.cameras):
            raise ValueError(f"camera.index={index} but scene {scene.name!r} has {len(scene.cameras)} camera(s)")
        camera = scene.cameras[index]
        return camera.world_T_cam, float(fov if fov is not None else camera.fov_x_deg)
    if fov is None:
        raise ValueError("camera.fov_x_deg is required with an explicit pose")
    return pose, float(fov)


def settings_from_node(cls: type, node: dict | None, prefix: str) -> Any:
    """The settings dataclass ``cls`` from a config node (a dict; None: the defaults); a key it does
    not know is an error naming ``<prefix>.<key>``, and so is a value of another kind than the
    key's default (a flag, an integer, a number; null only where the key's type takes it). Lists
    become tuples."""
    node = dict(node or {})
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(node) - known)
    renamed = [RENAMED_KEYS[f"{prefix}.{k}"] for k in unknown if f"{prefix}.{k}" in RENAMED_KEYS]
    if renamed:  # a preset written before the rename
        raise ValueError(renamed[0])
    if unknown:
        raise ValueError(
            f"unknown key(s) {', '.join(f'{prefix}.{k}' for k in unknown)}; "
            f"{prefix} takes {', '.join(sorted(known)) or 'no keys'}"
        )
    hints = typing.get_type_hints(cls)
    for field in dataclasses.fields(cls):
        if field.name not in node or (node[field.name] is None and type(None) in typing.get_args(hints[field.name])):
            continue  # a default, or null where the type takes it
        _check_kind(node[field.name], field.default, f"{prefix}.{field.name}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in node.items()})


def _check_kind(value: Any, default: Any, key: str) -> None:
    """Refuse, naming ``key``, a value of another kind than its default's where that is a flag, an
    integer or a number (text where a number belongs would otherwise fail deep inside a search, or
    a flag read as true); a key whose default is None, text or a list may take several kinds."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ValueError(f"{key} must be true or false, got {value!r}")
    elif isinstance(default, int):
        config_int(value, key)
    elif isinstance(default, float) and (isinstance(value, bool) or not isinstance(value, (int, float))):
        raise ValueError(f"{key} must be a number, got {value!r}")


def model_from_config(node: Any) -> DepthModel:
    """The ``model`` node's model: ``model=custom`` instantiates ``model.target(**model.args)``
    with its declared ``model.output_kind``; any other preset loads by name (and ``model.weights``).
    ``model.intrinsics`` (given, the default, or withheld) says whether a model that takes the
    camera's K receives it."""
    node = OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else dict(node)
    intrinsics = check_intrinsics(node.get("intrinsics") or "given")
    if node.get("name") == "custom":
        model = load_custom(node.get("target") or "", node.get("output_kind", "disparity"), node.get("args"))
    else:
        model = _preset_model(node)
    model.intrinsics = intrinsics
    return model


# the keys of every model node; any other key is a setting of the model (Marigold's), which
# load_model takes or refuses
_MODEL_KEYS = frozenset({"name", "hub_id", "output_kind", "weights", "intrinsics"})


def _preset_model(node: dict) -> DepthModel:
    """A preset's model by name (and ``model.weights``, and its settings); a hub id or output kind
    other than the preset's is refused naming the key."""
    preset = EMBEDDED.get(node["name"]) or PRESETS.get(node["name"])
    for key in ("hub_id", "output_kind"):
        if preset is not None and node.get(key) is not None and node[key] != getattr(preset, key):
            raise ValueError(
                f"model.{key}: the preset {node['name']!r} has {key} {getattr(preset, key)!r}, fixed by its "
                f"checkpoint, not {node[key]!r}; for other weights use model=huggingface model.name=<id or dir>"
            )
    settings = {key: value for key, value in node.items() if key not in _MODEL_KEYS}
    return load_model(node["name"], node.get("weights"), **settings)
