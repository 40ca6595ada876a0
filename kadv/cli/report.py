"""``kadv-report``: the study's tables, method comparison, transfer matrix and one HTML page for a sweep."""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import argparse
import sys
from pathlib import Path

from omegaconf import OmegaConf

from kadv.cli.common import USER_ERRORS, model_from_config, scene_from_config, shading_from_config
from kadv.models import DepthModel
from kadv.render import ExactRenderer
from kadv.report.build import write_report
from kadv.report.sweep import RunRecord

DESCRIPTION = """kadv-report: turns kadv-attack run directories into the study's tables and more.
Writes to OUT (default: <first path>/report), for each search method M in the runs:
table2_M.{md,csv} (adversarial L_depth and delta1 per model x scene) and table3_M.{md,csv} (change
from the init views); then methods.{md,csv} (each attack method's
gain, evaluations and seconds, when the runs hold more than one), transfer_delta1.{md,csv} and
transfer_l_depth.{md,csv} (every model scored on every model's adversarial views, re-rendered from
their saved poses), curves.png (anytime curves per model and method), and report.html
(self-contained: tables, curves, gallery, maps)."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kadv-report", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("paths", nargs="+", help="sweep directories or run directories")
    parser.add_argument("-o", "--out", type=Path, help="output folder (default: <first path>/report)")
    parser.add_argument("--no-transfer", action="store_true", help="skip the transfer matrix (no re-rendering)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


class _FromConfig:
    """A run's renderer and model, built from its saved config, once per scene and per model."""

    def __init__(self) -> None:
        self.renderers: dict[str, ExactRenderer] = {}
        self.models: dict[str, DepthModel] = {}

    def renderer_of(self, run: RunRecord) -> ExactRenderer:
        if run.scene not in self.renderers:
            config = OmegaConf.create(run.config)
            self.renderers[run.scene] = ExactRenderer(
                scene_from_config(config.scene), shading_from_config(config.render.shading)
            )
        return self.renderers[run.scene]

    def model_of(self, run: RunRecord) -> DepthModel:
        if run.model not in self.models:
            self.models[run.model] = model_from_config(run.config["model"])
        return self.models[run.model]


def main(argv: list[str] | None = None) -> None:
    """Write the report of the runs named on the command line."""
    args = _parser().parse_args(argv)
    try:
        sources = None if args.no_transfer else _FromConfig()
        written = write_report(
            args.paths,
            args.out,
            sources and sources.renderer_of,
            sources and sources.model_of,
            progress=not args.no_progress,
        )
    except USER_ERRORS as error:
        print(f"kadv-report: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)
    print("\n".join(str(path) for path in written))


if __name__ == "__main__":
    main()
