"""``kadv-report``: the study's tables, method comparison, transfer matrix and one HTML page for a sweep."""
from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import argparse
import sys
from pathlib import Path

from omegaconf import OmegaConf

from kadv.cli.common import (
    USER_ERRORS,
    model_from_config,
    scene_from_config,
    shading_from_config,
)
from kadv.losses import depth_loss
from kadv.render import ExactRenderer
from kadv.report.html import save_mean_curves, write_html
from kadv.report.sweep import (
    RunRecord,
    collect_runs,
    method_table,
    methods_of,
    table2,
    table3,
)
from kadv.report.transfer import transfer_tables

DESCRIPTION = """kadv-report: turns kadv-attack run directories into the study's tables and more.
Writes to OUT (default: <first path>/report), for each search method M in the runs:
table2_M.{md,csv} (adversarial L_depth and delta1 per model x scene) and table3_M.{md,csv} (change
from the init views); then methods.{md,csv} (each attack method's
gain, evaluations and seconds, when the runs hold more than one), transfer_delta1.{md,csv} and
transfer_l_depth.{md,csv} (every model scored on every model's adversarial views, re-rendered from
their saved poses), curves.png (anytime curves per model and method), and report.html
(self-contained: tables, curves, gallery, maps)."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="kadv-report", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("paths", nargs="+", help="sweep directories or run directories")
    parser.add_argument("-o", "--out", type=Path, help="output folder (default: <first path>/report)")
    parser.add_argument("--no-transfer", action="store_true", help="skip the transfer matrix (no re-rendering)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def report(paths: list[str], out: Path | None, transfer: bool = True, progress: bool = True) -> list[Path]:
    """Write every table, the curves and ``report.html``; returns the files written."""
    runs = collect_runs(paths)
    out = out or Path(paths[0]) / "report"
    tables, stems = [], []
    for method in methods_of(runs):
        tables += [table2(runs, method), table3(runs, method)]
        stems += [f"table2_{method}", f"table3_{method}"]
    methods = method_table(runs)
    if methods is not None:
        tables.append(methods)
        stems.append("methods")
    if transfer:
        renderers: dict[str, ExactRenderer] = {}
        models: dict[str, object] = {}

        def renderer_of(run: RunRecord) -> ExactRenderer:
            if run.scene not in renderers:
                config = OmegaConf.create(run.config)
                renderers[run.scene] = ExactRenderer(scene_from_config(config.scene),
                                                     shading_from_config(config.render.shading))
            return renderers[run.scene]

        def model_of(run: RunRecord):
            if run.model not in models:
                models[run.model] = model_from_config(run.config["model"])
            return models[run.model]

        loss_config = runs[0].config["loss"]
        loss = depth_loss(loss_config["kind"], loss_config.get("vgg_weights"), int(loss_config.get("window_size", 11)))
        tables += transfer_tables(runs, renderer_of, model_of, loss, loss_config.get("space", "disparity"), progress)
        stems += ["transfer_delta1", "transfer_l_depth"]
    written = [path for table, stem in zip(tables, stems) for path in table.write(out, stem)]
    curves = save_mean_curves(out / "curves.png", runs)
    written.append(curves)
    written.append(write_html(out / "report.html", tables, curves, runs))
    return written


def main(argv: list[str] | None = None) -> None:
    """Write the report of the runs named on the command line."""
    args = _parser().parse_args(argv)
    try:
        written = report(args.paths, args.out, transfer=not args.no_transfer, progress=not args.no_progress)
    except USER_ERRORS as error:
        print(f"kadv-report: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)
    print("\n".join(str(path) for path in written))


if __name__ == "__main__":
    main()
