"""The sweep report: tables, curves, gallery and maps in one self-contained HTML page (Jinja2)."""
from __future__ import annotations

import base64
import csv
import os
from collections import defaultdict
from pathlib import Path

import jinja2
import matplotlib.pyplot as plt
import numpy as np

from kadv.io import atomic_write
from kadv.report.sweep import RunRecord, Table, primary_method

__all__ = ["save_mean_curves", "write_html"]


def _best_restart_curves(run: RunRecord) -> list[np.ndarray]:
    """L_depth per step of each init view's best restart (gradient runs)."""
    best = {view["index"]: view["best_restart"] for view in run.summary["init_views"]}
    curves: dict[int, list[float]] = defaultdict(list)
    with open(run.path / "trajectory.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            index = int(row["init_view"])
            if best.get(index) is not None and int(row["restart"]) == best[index]:
                curves[index].append(float(row["l_depth"]))
    return [np.array(values) for values in curves.values()]


def save_mean_curves(path: Path, runs: list[RunRecord]) -> Path | None:
    """Mean L_depth per step for each model (best restarts of the gradient runs), with the 25-75%
    band across runs and init views."""
    by_model: dict[str, list[np.ndarray]] = defaultdict(list)
    for run in runs:
        if run.method == "gradient":
            by_model[run.model] += _best_restart_curves(run)
    if not by_model:
        return None
    figure, axis = plt.subplots(figsize=(6.4, 4.0))
    for model, curves in sorted(by_model.items()):
        length = min(len(c) for c in curves)
        stack = np.stack([c[:length] for c in curves])
        steps = np.arange(length)
        axis.plot(steps, stack.mean(axis=0), label=f"{model} ({len(curves)} runs)")
        axis.fill_between(steps, *np.percentile(stack, [25, 75], axis=0), alpha=0.25)
    axis.set_xlabel("step")
    axis.set_ylabel("L_depth (best restart)")
    axis.set_title("Mean L_depth per step, 25-75% band")
    axis.legend(fontsize=8)
    try:
        return atomic_write(path, lambda tmp: figure.savefig(tmp, format="png", dpi=100, bbox_inches="tight"))
    finally:
        plt.close(figure)


def _data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _gallery(runs: list[RunRecord], out_dir: Path) -> list[dict]:
    """Per model x scene: the strongest adversarial view of the primary method's runs."""
    method = primary_method(runs)
    best: dict[tuple[str, str], tuple[float, RunRecord, dict]] = {}
    for run in runs:
        if run.method != method:
            continue
        for view in run.summary["init_views"]:
            if view["adversarial"]:
                top = view["adversarial"][0]
                key = (run.model, run.scene)
                if key not in best or top["l_depth"] > best[key][0]:
                    best[key] = (top["l_depth"], run, top)
    return [{"model": model, "scene": scene, "l_depth": l_depth, "delta1": top["delta1"],
             "image": _data_uri(run.path / top["png"]), "map": _data_uri(run.path / "map.png"),
             "href": Path(os.path.relpath(run.path, out_dir)).as_posix() + "/"}
            for (model, scene), (l_depth, run, top) in sorted(best.items())]


def write_html(path: Path, tables: list[Table], curves: Path | None, runs: list[RunRecord]) -> Path:
    """Render ``report.html``: every table (sortable by clicking a header), the curves, the gallery of
    the worst adversarial views linking to their run folders, and the scene maps; images embedded."""
    environment = jinja2.Environment(loader=jinja2.PackageLoader("kadv.report", "templates"),
                                     autoescape=jinja2.select_autoescape(["html", "j2"]))
    html = environment.get_template("report.html.j2").render(
        tables=tables, curves=_data_uri(curves) if curves else None, gallery=_gallery(runs, path.parent),
        runs=len(runs), models=sorted({r.model for r in runs}), scenes=sorted({r.scene for r in runs}),
        methods=sorted({r.method for r in runs}),
        number=lambda v: f"{v:.4f}" if isinstance(v, float) else v)
    return atomic_write(path, lambda tmp: tmp.write_text(html))
