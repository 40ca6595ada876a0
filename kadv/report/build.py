"""``kadv-report``'s work: every table, the anytime curves and ``report.html`` for a set of runs."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from kadv.attack import Study
from kadv.models import DepthModel
from kadv.report.html import save_mean_curves, save_profile_curves, write_html
from kadv.report.sweep import (
    RunRecord,
    collect_runs,
    method_table,
    methods_of,
    profile_tables,
    profiles_of,
    table2,
    table3,
)
from kadv.report.transfer import transfer_tables

__all__ = ["write_report"]


def write_report(
    paths: list[str | Path],
    out: str | Path | None = None,
    study_of: Callable[[RunRecord], Study] | None = None,
    model_of: Callable[[RunRecord], DepthModel] | None = None,
    progress: bool = True,
) -> list[Path]:
    """Write Tables 2 and 3 per method, the method table, the profile tables and ``profiles.png``
    (profile runs), the transfer matrix, ``curves.png`` and ``report.html`` for the complete runs
    under ``paths``; returns the files written.

    Args:
        paths: sweep or run directories.
        out: output folder (default: ``<first path>/report``).
        study_of: a run's :class:`~kadv.attack.Study` (its scene, render and loss settings), to
            re-render its adversarial views for the transfer matrix; without it (or ``model_of``),
            no transfer matrix.
        model_of: a run's model, to score every run's adversarial views.
        progress: show a progress bar while re-rendering.
    """
    runs = collect_runs(paths)
    out = Path(out) if out is not None else Path(paths[0]) / "report"
    tables, stems = [], []
    for method in methods_of(runs):
        tables += [table2(runs, method), table3(runs, method)]
        stems += [f"table2_{method}", f"table3_{method}"]
    methods = method_table(runs)
    if methods is not None:
        tables.append(methods)
        stems.append("methods")
    for k, table in enumerate(profile_tables(runs)):
        tables.append(table)
        stems.append(f"profiles{k if k else ''}")
    if study_of is not None and model_of is not None:
        tables += transfer_tables(runs, study_of, model_of, progress)
        stems += ["transfer_delta1", "transfer_l_depth"]
    written = [path for table, stem in zip(tables, stems) for path in table.write(out, stem)]
    curves = save_mean_curves(out / "curves.png", runs)
    profiles = profiles_of(runs)
    drawn = save_profile_curves(out / "profiles.png", profiles) if profiles else None
    extra = [drawn] if drawn is not None else []
    return [*written, curves, *extra, write_html(out / "report.html", tables, curves, runs, drawn)]
