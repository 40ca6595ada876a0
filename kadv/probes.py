"""Probe scenes, each aimed at one known failure of depth models (:mod:`kadv.scenes.probes`)."""

from __future__ import annotations

from kadv.scenes.probes import (
    PROBES,
    dim_lamp,
    grazing_floor,
    photo_wall,
    probe_names,
    probe_scene,
    stairs,
    textureless_close,
    thin_structures,
    window,
)

__all__ = [
    "PROBES",
    "dim_lamp",
    "grazing_floor",
    "photo_wall",
    "probe_names",
    "probe_scene",
    "stairs",
    "textureless_close",
    "thin_structures",
    "window",
]
