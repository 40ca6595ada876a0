"""The scene a ``scene/`` config node names, from the node as a plain mapping (a run's saved
``config.yaml``, or the composed config through :func:`kadv.cli.common.scene_from_config`)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from kadv.catalogue.probes import probe_scene
from kadv.scenes.box_rooms import box_room
from kadv.scenes.load import load_scene
from kadv.scenes.procedural import ROOM_FEATURES, procedural_room
from kadv.scenes.scene import Scene

__all__ = ["scene_from_node"]


def scene_from_node(node: Mapping[str, Any], path: str | Path | None = None) -> Scene:
    """Build the scene of a ``scene/`` node (``kind``: box_room, procedural, probe or file).

    Args:
        node: the node's keys (``kind``, ``seed``, ``num_boxes``, a procedural room's feature shares,
            a probe's ``name``, ``path``, ``options``).
        path: for a file scene, read this file instead of the node's ``path`` (a moved scene).

    Raises:
        ValueError: an unknown kind.
        FileNotFoundError: a file scene whose file is missing.
    """
    kind = node.get("kind")
    if kind == "box_room":
        return box_room(seed=node.get("seed", 0), num_boxes=node.get("num_boxes", 4))
    if kind == "procedural":
        return procedural_room(seed=node.get("seed", 0), **{name: node[name] for name in ROOM_FEATURES if name in node})
    if kind == "probe":
        return probe_scene(node.get("name", ""), seed=node.get("seed", 0))
    if kind == "file":
        return load_scene(Path(path if path is not None else node["path"]).expanduser(), **(node.get("options") or {}))
    raise ValueError(f"scene.kind must be 'box_room', 'procedural', 'probe' or 'file', got {kind!r}")
