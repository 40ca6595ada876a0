"""Synthetic training and evaluation data rendered from procedural rooms."""

from __future__ import annotations

from kadv.datasets.procedural import (
    HELD_OUT_SEED,
    MAX_SQUEEZED_ASPECT,
    TRAINING_BAKE,
    RoomMix,
    ViewBatch,
    render_procedural_views,
    training_poses,
)

__all__ = [
    "HELD_OUT_SEED",
    "MAX_SQUEEZED_ASPECT",
    "TRAINING_BAKE",
    "RoomMix",
    "ViewBatch",
    "render_procedural_views",
    "training_poses",
]
