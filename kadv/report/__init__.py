"""Run artefacts: images, the run directory and its summary, sweep tables, the HTML report and the 3-D viewer.

The names below load on first use, so that a command writing only images (``kadv-render``) does
not import the attack, the models and the report's plotting.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from kadv._lazy import lazy_exports

_EXPORTS = {
    "SCHEMA_VERSION": "kadv.report.summary",
    "RunInfo": "kadv.report.summary",
    "RunSummary": "kadv.report.summary",
    "save_depth_png": "kadv.report.images",
    "save_rgb_png": "kadv.report.images",
    "write_report": "kadv.report.build",
    "write_run": "kadv.report.outputs",
    "view": "kadv.report.viewer",
}

if TYPE_CHECKING:  # the same names, for type checkers and the API reference
    from kadv.report.build import write_report
    from kadv.report.images import save_depth_png, save_rgb_png
    from kadv.report.outputs import write_run
    from kadv.report.summary import SCHEMA_VERSION, RunInfo, RunSummary
    from kadv.report.viewer import view

__all__ = [
    "SCHEMA_VERSION",
    "RunInfo",
    "RunSummary",
    "save_depth_png",
    "save_rgb_png",
    "view",
    "write_report",
    "write_run",
]

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
