"""Run artefacts: images, the run directory and its summary, sweep tables and the HTML report."""

from __future__ import annotations

from kadv.report.build import write_report
from kadv.report.images import save_depth_png, save_rgb_png
from kadv.report.run import write_run
from kadv.report.summary import SCHEMA_VERSION, RunInfo, RunSummary

__all__ = ["SCHEMA_VERSION", "RunInfo", "RunSummary", "save_depth_png", "save_rgb_png", "write_report", "write_run"]
