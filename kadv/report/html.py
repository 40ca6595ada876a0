"""The sweep report: tables, curves, gallery and maps in one self-contained HTML page (Jinja2)."""

from __future__ import annotations

import base64
import os
from collections import defaultdict
from pathlib import Path

import jinja2
import matplotlib.pyplot as plt
import numpy as np

from kadv.attack.profile import Profile, save_profile_panels
from kadv.attack.records import agreement_text
from kadv.io import atomic_write
from kadv.report.figures import loss_label
from kadv.report.summary import InitViewSummary, ViewMetrics
from kadv.report.sweep import RunRecord, Table

__all__ = ["save_mean_curves", "save_profile_curves", "write_html"]


def _anytime_gains(run: RunRecord, seconds: np.ndarray) -> list[np.ndarray]:
    """Per init view: the attacked loss of the best valid view found by each time on ``seconds``,
    less the init view's. The best view is the one of highest attacked loss, so this never falls."""
    gains = []
    for view in run.summary.init_views:
        times = np.array([p.seconds for p in view.anytime])
        values = np.array([p.loss for p in view.anytime]) - view.anytime[0].loss
        gains.append(values[np.clip(np.searchsorted(times, seconds, side="right") - 1, 0, None)])
    return gains


def save_mean_curves(path: Path, runs: list[RunRecord]) -> Path:
    """Anytime curves: the mean gain in the attacked loss of the best valid view found so far against
    seconds, per model, method and loss, with the 25-75% band across runs and init views."""
    longest = max(view.budget.seconds for run in runs for view in run.summary.init_views)
    seconds = np.linspace(0.0, longest, 101)
    groups: dict[str, list[np.ndarray]] = defaultdict(list)
    for run in runs:
        groups[f"{run.model}, {run.method}, {loss_label(run.summary.loss)}"] += _anytime_gains(run, seconds)
    figure, axis = plt.subplots(figsize=(6.4, 4.0))
    for label, curves in sorted(groups.items()):
        stack = np.stack(curves)
        axis.plot(seconds, stack.mean(axis=0), label=f"{label} ({len(curves)} init views)")
        axis.fill_between(seconds, *np.percentile(stack, [25, 75], axis=0), alpha=0.25)
    axis.set_xlabel("seconds per init view")
    axis.set_ylabel("attacked loss of the best view so far,\nless the init view's")
    axis.set_title("Anytime search: mean gain, 25-75% band")
    axis.legend(fontsize=8)
    try:
        return atomic_write(path, lambda tmp: figure.savefig(tmp, format="png", dpi=100, bbox_inches="tight"))
    finally:
        plt.close(figure)


def save_profile_curves(path: Path, profiles: dict[tuple[str, str, str], Profile]) -> Path:
    """One panel per scene: each model's (and method's) worst (solid) and typical (dashed) delta1
    against the radius, with bands over its seeds (:func:`kadv.attack.profile.save_profile_panels`)."""
    panels: dict[str, dict[str, Profile]] = defaultdict(dict)
    for (model, scene, method), profile in sorted(profiles.items()):
        panels[scene][f"{model} ({method}) {profile.score:.2f}"] = profile
    return save_profile_panels(path, dict(panels))


def _data_uri(path: Path, kind: str = "image/png") -> str:
    return f"data:{kind};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _worst_video(runs: list[RunRecord], out_dir: Path) -> dict | None:
    """The run whose kept view lost the most delta1 from its init view, when it wrote its video (the
    video follows that init view's search)."""
    drops = [
        (view.init.delta1 - view.adversarial[0].delta1, run, view)
        for run in runs
        if (run.path / "trajectory.mp4").is_file()
        for view in run.summary.init_views
        if view.adversarial
    ]
    if not drops:
        return None
    _, run, view = max(drops, key=lambda item: item[0])
    return {
        "model": run.model,
        "scene": run.scene,
        "method": run.method,
        "init_delta1": view.init.delta1,
        "delta1": view.adversarial[0].delta1,
        "agreement": agreement_text(view.agreement),
        "video": _data_uri(run.path / "trajectory.mp4", "video/mp4"),
        "href": Path(os.path.relpath(run.path, out_dir)).as_posix() + "/",
    }


def _gallery(runs: list[RunRecord], out_dir: Path) -> list[dict]:
    """Per model x scene: the strongest adversarial view of any method (adversarial views are valid,
    so never uninformative)."""
    best: dict[tuple[str, str], tuple[float, RunRecord, ViewMetrics, InitViewSummary]] = {}
    for run in runs:
        for view in run.summary.init_views:
            if view.adversarial:
                top = view.adversarial[0]
                key = (run.model, run.scene)
                if key not in best or top.l_depth > best[key][0]:
                    best[key] = (top.l_depth, run, top, view)
    return [
        {
            "model": model,
            "scene": scene,
            "method": run.method,
            "l_depth": l_depth,
            "delta1": top.delta1,
            "agreement": agreement_text(view.agreement),
            "image": _data_uri(run.path / top.png),
            "map": _data_uri(run.path / "map.png"),
            "href": Path(os.path.relpath(run.path, out_dir)).as_posix() + "/",
        }
        for (model, scene), (l_depth, run, top, view) in sorted(best.items())
    ]


def write_html(
    path: Path, tables: list[Table], curves: Path, runs: list[RunRecord], profiles: Path | None = None
) -> Path:
    """Render ``report.html``: every table (sortable by clicking a header), the curves, the profile
    curves (``profiles``, when profile runs are among the runs), the gallery of the worst adversarial
    views linking to their run folders, the worst failure's video and the scene maps; images and the
    video embedded."""
    environment = jinja2.Environment(
        loader=jinja2.PackageLoader("kadv.report", "templates"), autoescape=jinja2.select_autoescape(["html", "j2"])
    )
    html = environment.get_template("report.html.j2").render(
        tables=tables,
        curves=_data_uri(curves),
        profiles=None if profiles is None else _data_uri(profiles),
        gallery=_gallery(runs, path.parent),
        worst=_worst_video(runs, path.parent),
        runs=len(runs),
        models=sorted({r.model for r in runs}),
        scenes=sorted({r.scene for r in runs}),
        methods=sorted({r.method for r in runs}),
        number=lambda v: f"{v:.4f}" if isinstance(v, float) else v,
    )
    return atomic_write(path, lambda tmp: tmp.write_text(html))
