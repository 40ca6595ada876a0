"""Run artefacts: images, the run directory, sweep tables and the HTML report."""
from __future__ import annotations

from kadv.report.images import save_depth_png, save_rgb_png

__all__ = ["save_depth_png", "save_rgb_png"]
