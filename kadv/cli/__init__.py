"""Hydra entry points; the only place kadv imports Hydra.

Importing this package sets the process up (:func:`kadv.runtime.configure_runtime`) before any
command module loads torch: a console script imports ``kadv.cli`` first.
"""
from __future__ import annotations

from kadv.runtime import configure_runtime

configure_runtime()

__all__: list[str] = []
