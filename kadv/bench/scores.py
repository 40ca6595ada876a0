"""A suite's scores: the suite score with its interval over search seeds, an interval over scenes,
the best-known worst case, and paired differences between models.

The suite score is the mean over cells (scene, init view, radius) of the worst delta1 found, each
cell's worst averaged over the entry's seeds. Its interval over seeds answers "would other search
seeds give the same score on these cells": the cells are fixed and the standard error is
sqrt(sum_c s_c^2 / n_c) / N from each cell's sample variance s_c^2 over its n_c seeds. The interval
over scenes answers another question, "would it hold on other rooms": a t interval over the
per-scene means.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from kadv.bench.entry import Entry
from kadv.bench.suite import Suite

__all__ = ["Z95", "Pooled", "SuiteScore", "best_known", "paired_difference", "pool_units", "suite_score"]

Z95 = 1.959963984540054  # the normal quantile of a two-sided 95% interval


@dataclass(frozen=True)
class Pooled:
    """One model's worst delta1 per cell and seed, over one or more entries of the same model.

    Attributes:
        worst: (scenes x views, radii, seeds) the worst delta1 found within each radius.
        init: (scenes x views, seeds) delta1 at the init view.
        abs_rel: (scenes x views, radii, seeds) AbsRel at the worst view.
        scene_of: (scenes x views,) each view's scene index.
        seeds: the seeds, in the last axis's order.
    """

    worst: np.ndarray
    init: np.ndarray
    abs_rel: np.ndarray
    scene_of: np.ndarray
    seeds: tuple[int, ...]


def pool_units(suite: Suite, entries: list[Entry]) -> Pooled:
    """The cells of ``entries`` (complete, of ``suite``, disjoint seeds) as arrays."""
    seeds = tuple(seed for entry in entries for seed in entry.seeds)
    views, radii = suite.views, len(suite.protocol.radii)
    worst = np.full((len(views), radii, len(seeds)), np.nan)
    abs_rel = np.full_like(worst, np.nan)
    init = np.full((len(views), len(seeds)), np.nan)
    column = {seed: j for j, seed in enumerate(seeds)}
    row = {view: i for i, view in enumerate(views)}
    for entry in entries:
        for unit in entry.units:
            i, j = row[(unit.scene, unit.view)], column[unit.seed]
            worst[i, :, j] = [c.delta1 for c in unit.cells]
            abs_rel[i, :, j] = [c.abs_rel for c in unit.cells]
            init[i, j] = unit.delta1_init
    return Pooled(worst, init, abs_rel, np.array([s for s, _ in views]), seeds)


def _mean_and_se(values: np.ndarray) -> tuple[float, float]:
    """The mean over cells (rows) of each cell's mean over seeds (columns), and its standard error
    over seeds (NaN with one seed)."""
    cells = values.shape[0]
    mean = float(values.mean(axis=1).mean())
    if values.shape[1] < 2:
        return mean, math.nan
    return mean, float(math.sqrt((values.var(axis=1, ddof=1) / values.shape[1]).sum()) / cells)


def _interval(mean: float, se: float) -> tuple[float, float]:
    return (mean - Z95 * se, mean + Z95 * se)


@dataclass(frozen=True)
class SuiteScore:
    """A model's scores on a suite (see the module docstring).

    Attributes:
        overall, overall_se: the suite score over every cell, and its standard error over seeds.
        per_radius, per_radius_se: the same at each radius.
        scenes_interval: the 95% t interval of the overall score over the per-scene means.
        init: mean delta1 at the init views.
        drop: init minus the overall score.
        abs_rel: mean AbsRel at the worst views.
        per_scene: per scene name, the score at each radius.
        seeds: the seeds pooled.
    """

    overall: float
    overall_se: float
    per_radius: list[float]
    per_radius_se: list[float]
    scenes_interval: tuple[float, float]
    init: float
    drop: float
    abs_rel: float
    per_scene: dict[str, list[float]]
    seeds: tuple[int, ...]

    @property
    def overall_interval(self) -> tuple[float, float]:
        """The 95% interval over seeds of the overall score."""
        return _interval(self.overall, self.overall_se)

    @property
    def per_radius_interval(self) -> list[tuple[float, float]]:
        return [_interval(m, s) for m, s in zip(self.per_radius, self.per_radius_se)]

    def to_dict(self) -> dict:
        return asdict(self) | {
            "overall_interval": self.overall_interval,
            "per_radius_interval": self.per_radius_interval,
        }


def suite_score(suite: Suite, pooled: Pooled) -> SuiteScore:
    """The :class:`SuiteScore` of pooled cells."""
    radii = pooled.worst.shape[1]
    every = pooled.worst.transpose(1, 0, 2).reshape(-1, pooled.worst.shape[2])  # (radii x views, seeds)
    overall, overall_se = _mean_and_se(every)
    per_radius = [_mean_and_se(pooled.worst[:, k, :]) for k in range(radii)]
    scene_means = np.array([pooled.worst[pooled.scene_of == s].mean() for s in range(len(suite.scenes))])
    if len(scene_means) > 1:
        half = stats.t.ppf(0.975, len(scene_means) - 1) * scene_means.std(ddof=1) / math.sqrt(len(scene_means))
    else:
        half = math.nan
    centre = float(scene_means.mean())
    init = float(pooled.init.mean())
    return SuiteScore(
        overall=overall,
        overall_se=overall_se,
        per_radius=[m for m, _ in per_radius],
        per_radius_se=[s for _, s in per_radius],
        scenes_interval=(centre - half, centre + half),
        init=init,
        drop=init - overall,
        abs_rel=float(pooled.abs_rel.mean()),
        per_scene={
            scene.name: pooled.worst[pooled.scene_of == s].mean(axis=(0, 2)).tolist()
            for s, scene in enumerate(suite.scenes)
        },
        seeds=pooled.seeds,
    )


def best_known(pooled: Pooled) -> tuple[float, list[float]]:
    """The best-known worst case: per cell the lowest delta1 any seed found, averaged over the
    cells (overall, and per radius)."""
    lowest = pooled.worst.min(axis=2)
    return float(lowest.mean()), lowest.mean(axis=0).tolist()


def paired_difference(first: Pooled, second: Pooled) -> tuple[float, float, int]:
    """The mean over cells of ``first``'s worst minus ``second``'s, on the seeds both hold, and
    its standard error over seeds (within each cell, the difference's variance over the common
    seeds); and how many common seeds there were.

    Raises:
        ValueError: no common seed.
    """
    common = [seed for seed in first.seeds if seed in second.seeds]
    if not common:
        raise ValueError("the two models share no seed: a paired difference needs common seeds")
    a = first.worst[:, :, [first.seeds.index(s) for s in common]]
    b = second.worst[:, :, [second.seeds.index(s) for s in common]]
    difference = (a - b).reshape(-1, len(common))
    mean, se = _mean_and_se(difference)
    return mean, se, len(common)
