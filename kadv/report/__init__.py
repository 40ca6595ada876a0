"""Run artefacts: images written atomically."""
from __future__ import annotations

from kadv.io import atomic_write
from kadv.report.images import save_depth_png, save_rgb_png

__all__ = ["atomic_write", "save_depth_png", "save_rgb_png"]
