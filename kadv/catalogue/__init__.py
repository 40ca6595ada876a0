"""The scenes kadv builds by name: a ``scene/`` config node's scene (a box room, a generated room,
a probe, a file), and the probe scenes, each aimed at one known failure of depth models.

It comes after :mod:`kadv.render` in the package order: a probe may render (the photograph
on the photo wall is a generated room's render)."""

from __future__ import annotations

from kadv.catalogue.nodes import scene_from_node
from kadv.catalogue.probes import PROBES, probe_names, probe_scene

__all__ = ["PROBES", "probe_names", "probe_scene", "scene_from_node"]
