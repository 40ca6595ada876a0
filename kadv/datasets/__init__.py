"""Synthetic training and evaluation data rendered from procedural rooms."""

from __future__ import annotations

from kadv.datasets.procedural import ViewBatch, render_procedural_views

__all__ = ["ViewBatch", "render_procedural_views"]
