"""Probe scenes, each aimed at one known failure of depth models: the names of
:mod:`kadv.catalogue.probes`, where they are built."""

from __future__ import annotations

from kadv.catalogue import probes as _probes
from kadv.catalogue.probes import *  # noqa: F403

__all__ = _probes.__all__
