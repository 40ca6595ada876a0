"""The pooled worst case of models run together on a suite: each model scored again at the worst
poses the others' entries found, cell by cell and seed by seed (as RobustBench pools its attacks).
A separate column beside the suite score, never the suite score itself: it depends on which models
ran together."""

from __future__ import annotations

import numpy as np
import torch

from kadv.attack import Study
from kadv.bench.entry import Entry, suite_settings
from kadv.bench.suite import BenchError, Suite
from kadv.bench.verify import cell_context
from kadv.models import DepthModel

__all__ = ["pooled_worst"]


def pooled_worst(
    suite: Suite,
    entries: dict[str, Entry],
    models: dict[str, DepthModel],
    root=None,
    device: str | torch.device = "cpu",
) -> dict[str, tuple[float, list[float]]]:
    """Per model name: the mean over cells of the seed-averaged lowest delta1 of the model's own
    worst view and of the model at each other model's worst pose there (same init view, radius and
    seed), overall and per radius; on the seeds every model's entries hold. One model pass per
    other model a cell and seed.

    Raises:
        BenchError: fewer than two models, a model of ``models`` without an entry, or no seed
            common to all the models.
    """
    units: dict[str, dict[tuple[int, int, int], object]] = {}
    for entry in entries.values():
        units.setdefault(entry.model["name"], {}).update({u.key: u for u in entry.units})
    if len(models) < 2:
        raise BenchError(f"a pooled worst case needs two models or more, got {', '.join(models) or 'none'}")
    missing = sorted(set(models) - set(units))
    if missing:
        raise BenchError(f"no entry of {', '.join(missing)} among the entries")
    seeds = sorted(set.intersection(*({key[2] for key in units[name]} for name in models)))
    if not seeds:
        raise BenchError("the models' entries share no seed: a pooled worst case needs common seeds")
    radii = len(suite.protocol.radii)
    lowest = {name: np.full((len(suite.views), radii, len(seeds)), np.nan) for name in models}
    settings = suite_settings(suite, device)
    for s, scene in enumerate(suite.scenes):
        loaded = scene.load(root)
        study = None
        for name, model in models.items():
            study = Study.build(loaded, model, settings) if study is None else study.variant(model=model)
            for v, frozen in enumerate(scene.views):
                row = suite.views.index((s, v))
                for j, seed in enumerate(seeds):
                    own = units[name][(s, v, seed)]
                    for k in range(radii):
                        others = [units[o][(s, v, seed)].cells[k].params for o in models if o != name]
                        context = cell_context(study, suite, frozen.init_view(), k)
                        params = torch.tensor(others, dtype=torch.float64)
                        scored = context.score(0, params, torch.ones(len(others), dtype=torch.float64))
                        values = [own.cells[k].delta1] + [r.delta1 for r in scored if r.valid]
                        lowest[name][row, k, j] = min(values)
    return {
        name: (float(values.mean(axis=2).mean()), values.mean(axis=2).mean(axis=0).tolist())
        for name, values in lowest.items()
    }
