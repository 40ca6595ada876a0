"""Transfer: each model's adversarial views, re-rendered from their saved poses, scored by every model."""

from __future__ import annotations

import dataclasses
import statistics
from collections import defaultdict
from collections.abc import Callable

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack import Study
from kadv.losses import depth_metrics, kind_fit
from kadv.models import DepthModel
from kadv.report.sweep import RunRecord, Table, main_method

__all__ = ["transfer_tables"]


def _adversarial_poses(run: RunRecord) -> tuple[torch.Tensor, torch.Tensor]:
    """The run's adversarial poses (N, 4, 4) and intrinsics (N, 3, 3), from the views' .npz files."""
    poses, Ks = [], []
    for view in run.summary.init_views:
        for adversarial in view.adversarial:
            arrays = np.load(run.path / adversarial.png.replace(".png", ".npz"))
            poses.append(torch.from_numpy(arrays["world_T_cam"]).double())
            Ks.append(torch.from_numpy(arrays["K"]).double())
    return torch.stack(poses), torch.stack(Ks)


def transfer_tables(
    runs: list[RunRecord],
    study_of: Callable[[RunRecord], Study],
    model_of: Callable[[RunRecord], DepthModel],
    progress: bool = True,
) -> tuple[Table, Table]:
    """delta1 and L_depth of every model (columns) on every model's adversarial views (rows).

    Each run's adversarial poses are re-rendered exactly at the run's size by its study
    (``study_of``: its scene, render and loss settings) and scored by each model in the sweep
    (``model_of``); cells average over scenes and views. The diagonal reproduces the runs' own scores.
    """
    method = main_method(runs)
    runs = [r for r in runs if r.method == method]
    models = {r.model: r for r in runs}
    names = sorted(models)
    scores: dict[tuple[str, str], dict[str, list[float]]] = defaultdict(lambda: {"delta1": [], "l_depth": []})
    kinds: dict[str, str] = {}
    with tqdm(total=len(runs) * len(names), desc="transfer: re-rendering views", disable=not progress) as bar:
        for run in runs:
            # every model is scored in its own output kind's space and alignment (a metric model's
            # scale and shift too, so that relative and metric models share one fit)
            study = study_of(run)
            study = study.variant(loss=dataclasses.replace(study.settings.loss, alignment=None))
            renderer = study.renderer
            poses, Ks = _adversarial_poses(run)
            height, width = run.summary.height, run.summary.width
            supersample = int(run.config.get("render", {}).get("supersample", 1))
            with torch.no_grad():
                out = renderer.render(poses, Ks, height, width, supersample=supersample).to("cpu")
                for name in names:
                    objective = study.variant(model=model_of(models[name])).objective
                    model = objective.model
                    kinds[name] = model.output_kind
                    prediction = model(out.rgb, Ks)
                    l_depth = objective.l_depth(out.depth.double(), prediction.double(), out.mask)
                    delta1 = depth_metrics(prediction.double(), out.depth.double(), out.mask, model.output_kind)[
                        "delta1"
                    ]
                    scores[run.model, name]["delta1"] += delta1.tolist()
                    scores[run.model, name]["l_depth"] += l_depth.tolist()
                    bar.update(1)
    tables = []
    fits = "; ".join(f"{name}: {' in '.join(reversed(kind_fit(kinds[name])))}" for name in names)
    for key, title in (
        ("delta1", f"Transfer: delta1 of each model (columns) on each model's adversarial views (rows); fitted {fits}"),
        ("l_depth", "Transfer: L_depth of each model (columns) on each model's adversarial views (rows)"),
    ):
        table = Table(title, ["views of \\ scored by", *names])
        for source in names:
            table.rows.append([source] + [statistics.mean(scores[source, target][key]) for target in names])
        tables.append(table)
    return tables[0], tables[1]
