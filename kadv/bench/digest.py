"""A scene's content digest: what kadv loaded (geometry, every material field, textures, lights),
quantised so that another loader version's or CPU's rounding leaves it unchanged, and nothing of
the file's name, its folder, the bake or the cameras."""

from __future__ import annotations

import hashlib
from dataclasses import asdict, fields

import numpy as np

from kadv.scenes import Scene

__all__ = ["COLOUR_LEVELS", "LENGTH_STEP", "scene_digest"]

LENGTH_STEP = 1e-6  # metres, and the step of every other real number but colours
COLOUR_LEVELS = 255  # colours, textures and masks to 8 bits
_DIRECTION_STEP = 1e-4  # unit normals: float32 normals renormalised differ in the 7th digit
_FORMAT = "kadv-scene-digest-1"
# material fields newer than the format, with their defaults
_LATER_FIELDS = {"mirror": False}


def _fixed(values, step: float) -> bytes:
    """``values`` rounded to multiples of ``step`` as little-endian int64 bytes (NaN as a marker)."""
    array = np.asarray(values, np.float64)
    finite = np.isfinite(array)
    steps = np.where(finite, np.round(np.where(finite, array, 0.0) / step), np.iinfo(np.int64).min)
    return repr(array.shape).encode() + steps.astype("<i8").tobytes()


def _colour(values) -> bytes:
    return _fixed(np.clip(np.asarray(values, np.float64), 0.0, 1.0) * COLOUR_LEVELS, 1.0)


def _material(material) -> bytes:
    """Every field of a material but its name (a label), each to its own quantum; a field added
    after the format (:data:`_LATER_FIELDS`) only where it differs from its default, so that the
    digests of scenes without it stay as they were."""
    parts = []
    for field in fields(material):
        value = getattr(material, field.name)
        if field.name == "name" or (field.name in _LATER_FIELDS and value == _LATER_FIELDS[field.name]):
            continue
        if field.name in ("base_color", "texture", "opacity"):
            parts.append(b"-" if value is None else _colour(value))
        elif value is None or isinstance(value, bool):
            parts.append(repr(value).encode())
        else:
            parts.append(_fixed(value, LENGTH_STEP))
    return b"|".join(parts)


def scene_digest(scene: Scene) -> str:
    """SHA-256 of ``scene`` as loaded: positions and other lengths to :data:`LENGTH_STEP`, normals
    to 1e-4, colours, textures and masks to 8 bits, every material field, the lights and emitters;
    the scene's name, cameras, trajectory and bake settings left out. The same content in another
    folder gives the same digest; a moved vertex or an edited texel does not.

    Examples:
        >>> from kadv.scenes import box_room
        >>> scene_digest(box_room(seed=0)) == scene_digest(box_room(seed=0)) != scene_digest(box_room(seed=1))
        True
    """
    digest = hashlib.sha256(_FORMAT.encode())
    for values, step in (
        (scene.vertices, LENGTH_STEP),
        (scene.uvs, LENGTH_STEP),
        (scene.normals, _DIRECTION_STEP),
        (scene.lights, LENGTH_STEP),
    ):
        digest.update(_fixed(values, step))
    digest.update(np.asarray(scene.faces, "<i8").tobytes() + np.asarray(scene.material_ids, "<i8").tobytes())
    for material in scene.materials:
        digest.update(_material(material))
    digest.update(b"-" if scene.colors is None else _colour(scene.colors))
    for name, value in asdict(scene.emitters).items():
        if name != "defaulted":
            digest.update(name.encode() + (b"-" if value is None else _fixed(value, LENGTH_STEP)))
    digest.update(repr((scene.emitters.defaulted, scene.captured_by is not None)).encode())
    return digest.hexdigest()
