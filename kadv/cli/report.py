"""``kadv-report``: the study's tables, method comparison, transfer matrix and one HTML page for a sweep."""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import argparse
import sys
from pathlib import Path

from omegaconf import OmegaConf

from kadv.attack import Study
from kadv.cli.common import USER_ERRORS, loss_settings, model_from_config, scene_from_config, study_settings
from kadv.models import DepthModel
from kadv.report.build import write_report
from kadv.report.sweep import RunRecord, collect_runs

DESCRIPTION = """kadv-report: turns kadv-attack run directories into the study's tables and more.
Writes to OUT (default: <first path>/report), for each search method M in the runs:
table2_M.{md,csv} (adversarial L_depth and delta1 per model x scene) and table3_M.{md,csv} (change
from the init views); then methods.{md,csv} (each attack method's
gain, model passes and seconds, when the runs hold more than one), transfer_delta1.{md,csv} and
transfer_l_depth.{md,csv} (every model scored on every model's adversarial views, re-rendered from
their saved poses), curves.png (anytime curves per model and method), and report.html
(self-contained: tables, curves, gallery, maps); with --reference, reference_<run>.{md,csv} (each
kept adversarial view and its init view re-rendered by Mitsuba 3 and scored on both renderers).
Paths may also be suite entries (kadv-bench's entry.json files): for them it writes
table2_<suite>.{md,csv}, the study's Table 2 at the suite's largest radius (--suite names a suite
file when the entries' suite is not a shipped one)."""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="kadv-report", description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("paths", nargs="+", help="sweep directories or run directories")
    parser.add_argument("-o", "--out", type=Path, help="output folder (default: <first path>/report)")
    parser.add_argument("--no-transfer", action="store_true", help="skip the transfer matrix (no re-rendering)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--reference",
        action="store_true",
        help="re-render every kept adversarial view and its init view with Mitsuba 3 (the reference extra) "
        "and write reference_<run>.{md,csv}: delta1 init -> adversarial on kadv's renders and on Mitsuba's",
    )
    parser.add_argument("--reference-spp", type=int, default=64, help="Mitsuba samples per pixel (denoised)")
    parser.add_argument("--suite", help="the suite file of the entries given (default: their shipped suite)")
    return parser


class _FromConfig:
    """A run's study and model, built from its saved config: one exact renderer per scene, one
    model per model name."""

    def __init__(self) -> None:
        self.studies: dict[str, Study] = {}
        self.models: dict[str, DepthModel] = {}

    def study_of(self, run: RunRecord) -> Study:
        """The study of the run's scene and model, with its render and loss settings."""
        config = OmegaConf.create(run.config)
        loss = loss_settings(config.loss)
        if run.scene not in self.studies:
            scene = scene_from_config(config.scene)
            settings = study_settings(scene, config.render, loss=loss)
            self.studies[run.scene] = Study.build(scene, self.model_of(run), settings)
        return self.studies[run.scene].variant(model=self.model_of(run), loss=loss)

    def model_of(self, run: RunRecord) -> DepthModel:
        if run.model not in self.models:
            self.models[run.model] = model_from_config(run.config["model"])
        return self.models[run.model]


def main(argv: list[str] | None = None) -> None:
    """Write the report of the runs named on the command line."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.reference_spp < 1:  # before the report's minutes, not after them
        parser.error(f"--reference-spp must be >= 1, got {args.reference_spp}")
    entries = [path for path in args.paths if Path(path).suffix == ".json"]
    runs = [path for path in args.paths if path not in entries]
    try:
        written = _entry_tables(entries, args.suite, args.out)
        sources = None if args.no_transfer or not runs else _FromConfig()
        if runs:
            written += write_report(
                runs,
                args.out,
                sources and sources.study_of,
                sources and sources.model_of,
                progress=not args.no_progress,
            )
        if args.reference:
            written += _reference_tables(args, sources or _FromConfig())
    except USER_ERRORS as error:
        print(f"kadv-report: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)
    print("\n".join(str(path) for path in written))


def _entry_tables(paths: list[str], suite: str | None, out: Path | None) -> list[Path]:
    """The study's Table 2 of suite entries, one per suite (``out``: None, beside the first entry)."""
    if not paths:
        return []
    out = out if out is not None else Path(paths[0]).parent / "report"
    from kadv.bench import load_suite, read_entries, suite_table2
    from kadv.bench.verify import check_complete

    entries = read_entries(paths)
    by_suite: dict[str, dict] = {}
    for path, entry in entries.items():
        by_suite.setdefault(suite or entry.suite["name"], {})[path] = entry
    written = []
    for name, group in by_suite.items():
        frozen = load_suite(name)
        for path, entry in group.items():  # of the suite, and holding every cell the table averages
            check_complete(entry, frozen, f"entry {path}")
        written += suite_table2(frozen, group).write(out, f"table2_{frozen.name}")
    return written


def _reference_tables(args: argparse.Namespace, sources: _FromConfig) -> list[Path]:
    """Mitsuba's verdict on each run whose scene is a Mitsuba XML file: one table per run."""
    try:
        import mitsuba  # noqa: F401
    except ImportError as error:
        raise ValueError("--reference needs Mitsuba 3: pip install 'kadv[reference]'") from error
    from kadv.diagnostics.reference import survival, survival_table

    out = args.out if args.out is not None else Path(args.paths[0]) / "report"
    written = []
    for run in collect_runs(args.paths):
        scene = run.config.get("scene", {})
        path = Path(str(scene.get("path", ""))).expanduser()
        if scene.get("kind") != "file" or path.suffix.lower() != ".xml":
            print(
                f"kadv-report: {run.path}: its scene is not a Mitsuba XML file; no reference renders", file=sys.stderr
            )
            continue
        if not path.is_file():
            raise FileNotFoundError(f"{run.path}: its scene file {path} is gone; the reference needs it")
        rows = survival(
            path, run.summary.init_views, sources.study_of(run).renderer, sources.model_of(run),
            run.summary.height, run.summary.width, args.reference_spp, progress=not args.no_progress,
        )  # fmt: skip
        title = f"{run.model} on {run.scene} ({run.method}): delta1 on kadv's renders and on Mitsuba's"
        written += survival_table(title, rows).write(out, f"reference_{run.path.name}")
    if not written:
        raise ValueError("--reference: no run's scene is a Mitsuba XML file (generated rooms have none)")
    return written


if __name__ == "__main__":
    main()
