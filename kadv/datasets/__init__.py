"""Synthetic training and evaluation data rendered from procedural rooms."""

from __future__ import annotations

from kadv.datasets.procedural import HELD_OUT_SEED, ViewBatch, render_procedural_views

__all__ = ["HELD_OUT_SEED", "ViewBatch", "render_procedural_views"]
