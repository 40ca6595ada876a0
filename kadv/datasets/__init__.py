"""Synthetic training and evaluation data rendered from procedural rooms, and scan-like rooms made
from them in the scan datasets' layouts."""

from __future__ import annotations

from kadv.datasets.room_views import (
    HELD_OUT_SEED,
    MAX_SQUEEZED_ASPECT,
    TRAINING_BAKE,
    RoomMix,
    ViewBatch,
    render_procedural_views,
    training_poses,
)
from kadv.datasets.scan_rooms import SCAN_LAYOUTS, ScanLike, ScanLikeSettings, scan_like, write_scan

__all__ = [
    "HELD_OUT_SEED",
    "MAX_SQUEEZED_ASPECT",
    "SCAN_LAYOUTS",
    "TRAINING_BAKE",
    "RoomMix",
    "ScanLike",
    "ScanLikeSettings",
    "ViewBatch",
    "render_procedural_views",
    "scan_like",
    "training_poses",
    "write_scan",
]
