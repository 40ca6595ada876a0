"""Probe scenes, each aimed at one known failure of depth models: the names of
:mod:`kadv.scenes.probes`, where they are built."""

from __future__ import annotations

from kadv.scenes import probes as _probes
from kadv.scenes.probes import *  # noqa: F403

__all__ = _probes.__all__
