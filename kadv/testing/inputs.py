"""The models and scenes that kadv's checks take, resolved from what a user's test passes."""

from __future__ import annotations

from pathlib import Path

__all__ = ["SCENE_KINDS", "RobustnessInputError", "resolve_model", "resolve_scene", "scene"]

SCENE_KINDS = ("box_room", "procedural", "probe/<name>", "a scene file's path")


class RobustnessInputError(ValueError):
    """A check's input is wrong (its message names it): a usage error, not a failing model."""


def scene(name: str | Path, seed: int = 0):
    """A scene by name: ``"box_room"``, ``"procedural"`` (a furnished room), ``"probe/<name>"`` (a
    probe of :mod:`kadv.probes`), or the path of a scene file (``.xml``, ``.glb``, ``.obj``, ...).

    Raises:
        RobustnessInputError: an unknown name, listing what there is, or a file that cannot load.
    """
    from kadv.catalogue import scene_from_node

    text = str(name)
    if text in ("box_room", "procedural"):
        node = {"kind": text, "seed": seed}
    elif text.startswith("probe/"):
        node = {"kind": "probe", "name": text.removeprefix("probe/"), "seed": seed}
    elif Path(text).suffix:
        node = {"kind": "file", "path": text}
    else:
        raise RobustnessInputError(f"no scene {text!r}: give one of {', '.join(SCENE_KINDS)}")
    try:
        return scene_from_node(node)
    except (ValueError, FileNotFoundError) as error:
        raise RobustnessInputError(str(error)) from error


def resolve_scene(value):
    """A :class:`kadv.scenes.Scene` as it is, else :func:`scene` of it."""
    from kadv.scenes import Scene

    return value if isinstance(value, Scene) else scene(value)


def resolve_model(value):
    """A checked :class:`kadv.models.DepthModel` from a name or folder (:func:`kadv.load_model`), a
    DepthModel, or ``(torch module, output kind)``.

    Raises:
        RobustnessInputError: a model that cannot load, or one that does not map (B, 3, H, W)
            images to (B, 1, H, W) finite maps.
    """
    import torch

    from kadv.errors import WeightsUnavailable
    from kadv.models import DepthModel, check_depth_model, load_model, wrap_model

    try:
        if isinstance(value, (str, Path)):
            return load_model(value)
        if isinstance(value, DepthModel):
            return check_depth_model(value)
        if isinstance(value, tuple) and len(value) == 2 and isinstance(value[0], torch.nn.Module):
            return wrap_model(value[0], value[1])
    except (ValueError, FileNotFoundError, WeightsUnavailable) as error:
        raise RobustnessInputError(" ".join(str(error).split())) from error
    if isinstance(value, torch.nn.Module):
        raise RobustnessInputError(
            f"model: a torch module needs its output kind: pass ({type(value).__name__}(...), 'depth' or 'disparity')"
        )
    raise RobustnessInputError(
        f"model: expected a preset name, a hub id, a folder, a DepthModel or (module, output kind), got {value!r}"
    )
