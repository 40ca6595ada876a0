"""The probe scorecard: every model's robustness profile on every probe scene, as one table, one
ranking and one picture."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kadv.testing.inputs import RobustnessInputError
from kadv.testing.profile import (
    DEFAULT_RADII,
    FAIL_BELOW,
    TYPICAL_VIEWS,
    Profile,
    pool_worst_views,
    profile_settings,
    save_profile_panels,
    save_worst_pictures,
    seed_run,
)

__all__ = ["PairedDifference", "Scorecard", "paired_difference", "scorecard"]

_AREAS = {"worst": "worst-case area", "typical": "typical area"}
_UNITS = {"worst": "worst_scores", "typical": "scores"}  # a profile's per-seed areas
_BOOTSTRAP_DRAWS = 4000


@dataclass(frozen=True)
class PairedDifference:
    """The mean of paired differences a - b over units (probes and seeds) and its 95% bootstrap
    interval (percentiles of the mean over resampled units).

    Attributes:
        mean: the mean difference.
        low, high: the interval's ends.
        units: the number of pairs.
    """

    mean: float
    low: float
    high: float
    units: int

    @property
    def separated(self) -> bool:
        """Whether the interval excludes 0: a and b differ beyond the units' spread."""
        return self.low > 0 or self.high < 0


def paired_difference(a: list[float], b: list[float], seed: int = 0, strata: list | None = None) -> PairedDifference:
    """a - b over paired units, with a 95% percentile bootstrap interval of the mean (deterministic
    for ``seed``); a unit where either is NaN is left out.

    ``strata``: a label per unit (a scorecard's probe). Where every stratum keeps two units or more,
    the bootstrap resamples units within each stratum (the strata fixed, as a scorecard's probes
    are: the interval is what a new draw of each probe's rooms and searches would move the mean);
    otherwise, and without strata, it resamples all units together. Either way the n differences
    resampled together are first spread about their mean by sqrt(n / (n - 1)), so that a few units
    do not understate their variance (Davison and Hinkley, *Bootstrap Methods*, 1997, section 3.7).

    Examples:
        >>> d = paired_difference([0.9, 0.8, 0.85], [0.7, 0.75, 0.6])
        >>> round(d.mean, 3), d.separated
        (0.167, True)
        >>> paired_difference([0.9, 0.7], [0.8, 0.8]).separated
        False
    """
    if len(a) != len(b) or (strata is not None and len(strata) != len(a)):
        counts = f"{len(a)} units against {len(b)}" + ("" if strata is None else f" and {len(strata)} strata labels")
        raise RobustnessInputError(f"paired_difference: {counts}; pair the same units")
    differences = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    kept = ~np.isnan(differences)
    differences = differences[kept]
    if len(differences) == 0:
        return PairedDifference(float("nan"), float("nan"), float("nan"), 0)
    rng = np.random.default_rng(seed)
    groups = [differences] if strata is None else _strata(differences, np.asarray(strata, dtype=object)[kept])
    if min(len(group) for group in groups) < 2:
        groups = [differences]
    sums = np.zeros(_BOOTSTRAP_DRAWS)
    for group in groups:
        if len(group) > 1:
            group = group.mean() + math.sqrt(len(group) / (len(group) - 1)) * (group - group.mean())
        sums += group[rng.integers(0, len(group), size=(_BOOTSTRAP_DRAWS, len(group)))].sum(axis=1)
    means = sums / len(differences)
    low, high = np.percentile(means, [2.5, 97.5])
    return PairedDifference(float(differences.mean()), float(low), float(high), len(differences))


def _strata(values: np.ndarray, labels: np.ndarray) -> list[np.ndarray]:
    """``values`` grouped by ``labels``, in the order the labels first appear."""
    order = list(dict.fromkeys(labels.tolist()))
    return [values[labels == label] for label in order]


@dataclass(frozen=True)
class Scorecard:
    """Profiles by probe and model.

    Attributes:
        models: the models' names.
        probes: the probes' names.
        results: ``results[probe][model]``, over all the seeds.
    """

    models: list[str]
    probes: list[str]
    results: dict[str, dict[str, Profile]]

    def to_dict(self) -> dict:
        """The models, probes and every profile (:meth:`Profile.to_dict`), as plain JSON values."""
        results = {probe: {model: p.to_dict() for model, p in row.items()} for probe, row in self.results.items()}
        return {"models": list(self.models), "probes": list(self.probes), "results": results}

    @classmethod
    def from_dict(cls, data: dict) -> Scorecard:
        """The scorecard :meth:`to_dict` wrote: its rankings and table computed again."""
        results = {
            probe: {model: Profile.from_dict(p) for model, p in row.items()} for probe, row in data["results"].items()
        }
        return cls(list(data["models"]), list(data["probes"]), results)

    def unit_scores(self, model: str, kind: str = "typical") -> list[float]:
        """The model's area under its ``kind`` curve ("typical" or "worst") per probe and seed, in
        the order of :attr:`probes` then seeds: the units two models are paired on (the same room,
        init views and drawn views)."""
        return [value for _, value in self._units(model, kind)]

    def _units(self, model: str, kind: str) -> list[tuple[str, float]]:
        """(probe, area) per probe and seed, in the order of :meth:`unit_scores`."""
        return [(probe, value) for probe in self.probes for value in getattr(self.results[probe][model], _UNITS[kind])]

    def difference(self, a: str, b: str, kind: str = "typical") -> PairedDifference:
        """``a``'s area minus ``b``'s, paired probe by probe and seed by seed, with its bootstrap
        interval: over the seeds within each probe when each probe has two seeds or more (the probes
        fixed), over the probes otherwise."""
        units = self._units(a, kind)
        return paired_difference(
            [value for _, value in units], self.unit_scores(b, kind), strata=[probe for probe, _ in units]
        )

    def ranking(self, kind: str = "typical") -> str:
        """``ranking (typical area): a (0.61) > b (0.55)``: the models by mean area under their
        ``kind`` curve, highest first; ``>`` only where the 95% bootstrap interval of the paired
        difference between neighbours excludes 0, ``=`` (tied) otherwise."""
        means = {model: float(np.mean(self.unit_scores(model, kind))) for model in self.models}
        order = sorted(self.models, key=lambda model: -means[model])
        text = f"ranking ({_AREAS[kind]}): {order[0]} ({means[order[0]]:.3f})"
        for better, worse in itertools.pairwise(order):
            text += f" {'>' if self.difference(better, worse, kind).low > 0 else '='} {worse} ({means[worse]:.3f})"
        if len(order) > 1 and " = " in text:
            text += "; '=': the paired difference's 95% interval holds 0 (tied)"
        return text

    def differences(self, kind: str = "typical") -> list[str]:
        """One line per pair of models: the paired difference of their ``kind`` areas, its 95%
        interval, and on how many probes alone the interval excludes 0."""
        lines = []
        for a, b in itertools.combinations(self.models, 2):
            overall = self.difference(a, b, kind)
            probes = sum(
                paired_difference(
                    getattr(self.results[p][a], _UNITS[kind]), getattr(self.results[p][b], _UNITS[kind])
                ).separated
                for p in self.probes
            )
            lines.append(
                f"{a} - {b} ({_AREAS[kind]}): {overall.mean:+.3f} (95% {overall.low:+.3f} to {overall.high:+.3f}, "
                f"{overall.units} probe-seed pairs); apart on {probes} of {len(self.probes)} probes"
            )
        return lines

    def markdown(self) -> str:
        """Per probe and model: the worst delta1 at each radius, the search noise at the largest, the
        failure rate there, the worst-case area, the resilience and the typical area (mean ± spread
        over the seeds); the models' means and costs; the paired rankings under both areas and the
        differences behind them."""
        radii = self.results[self.probes[0]][self.models[0]].radii
        largest = f"{radii[-1][0]:g}°/{radii[-1][1]:g} m"
        lines = [
            "| probe | model | "
            + " | ".join(f"worst delta1 {d:g}°/{m:g} m" for d, m in radii)
            + f" | agreement {largest} | search noise {largest} | failure rate {largest} | worst-case area | "
            "resilience | typical area |",
            "|---|---|" + "---|" * (len(radii) + 6),
        ]
        for probe in self.probes:
            for model in self.models:
                profile = self.results[probe][model]
                worst = " | ".join(f"{v:.3f}" for v in profile.worst)
                noise = profile.search_noise[-1]
                lines.append(
                    f"| {probe} | {model} | {worst} | {profile.agreement_text(len(radii) - 1)} | "
                    f"{'n/a' if np.isnan(noise) else f'{noise:.3f}'} | "
                    f"{profile.failure_rate[-1]:.0%} | "
                    f"{profile.worst_score:.3f} ± {np.ptp(profile.worst_scores):.3f} | {profile.resilience:.3f} | "
                    f"{profile.score:.3f} ± {profile.score_spread:.3f} |"
                )
        blank = " | ".join([""] * (len(radii) + 3))
        for model in self.models:
            worst, typical = self.unit_scores(model, "worst"), self.unit_scores(model, "typical")
            resilience = np.mean([self.results[p][model].resilience for p in self.probes])
            lines.append(
                f"| **mean** | {model} | {blank} | **{np.mean(worst):.3f}** | **{resilience:.3f}** | "
                f"**{np.mean(typical):.3f}** |"
            )
        notes = [
            f"delta1 after {self.results[self.probes[0]][self.models[0]].alignment} alignment; agreement: the "
            "searches' runs that reached their worst, of the runs made, over seeds and init views "
            "(alone: init views whose worst one run found and none confirmed; attack.restarts); search noise: the "
            "sd of the worst over the search seeds with the init views fixed (n/a: one search seed); ± after an "
            "area: its spread over the seeds, init views and searches together"
        ]
        for model in self.models:
            costs = [self.results[p][model].cost for p in self.probes]
            notes.append(
                f"cost of {model} per init view (mean over probes): "
                f"{np.mean([c['search_passes'] for c in costs]):.0f} model passes searching, "
                f"{np.mean([c['search_seconds'] for c in costs]):.1f} s; "
                f"{np.mean([c['draw_passes'] for c in costs]):.0f} passes on drawn views"
            )
        rankings = [self.ranking("worst"), self.ranking("typical")]
        if len(self.models) > 1:
            rankings += self.differences("worst") + self.differences("typical")
        return "\n".join(lines) + "\n\n" + "\n".join(notes) + "\n\n" + "\n".join(rankings)

    def save_png(self, path: str | Path) -> Path:
        """One panel per probe: each model's worst (solid) and typical (dashed) delta1 against the
        radius, with bands over the seeds."""
        panels = {
            probe: {f"{model} {profile.score:.2f}": profile for model, profile in self.results[probe].items()}
            for probe in self.probes
        }
        return save_profile_panels(path, panels)


def _checked_inputs(models: list, probes: list[str] | None, seeds) -> tuple[list[str], tuple, list]:
    """A scorecard's probes (None: all), seeds and loaded models, or :class:`RobustnessInputError`
    naming what is wrong: an unknown probe, no model, no seed, two models of one name."""
    from kadv.catalogue.probes import PROBES
    from kadv.testing.inputs import resolve_model

    probes = list(PROBES) if probes is None else list(probes)
    unknown = [name for name in probes if name not in PROBES]
    if unknown:
        raise RobustnessInputError(f"no probe scene {unknown[0]!r}; the probes are: {', '.join(PROBES)}")
    if not models:
        raise RobustnessInputError("scorecard needs at least one model")
    seeds = tuple(seeds)
    if not seeds:
        raise RobustnessInputError("seeds is empty: give at least one seed")
    loaded = [resolve_model(model) for model in models]
    names = [model.name for model in loaded]
    if len(set(names)) != len(names):
        raise RobustnessInputError(f"models: each must have its own name, got {names}")
    return probes, seeds, loaded


def scorecard(
    models: list,
    probes: list[str] | None = None,
    *,
    seeds=(0,),
    envelope="upright",
    radii=DEFAULT_RADII,
    typical_views: int = TYPICAL_VIEWS,
    fail_below: float = FAIL_BELOW,
    search_seeds: int = 1,
    pool: bool = True,
    progress: bool = False,
    **options,
) -> Scorecard:
    """Profile each model on each probe scene (:func:`kadv.testing.robustness_profile`), each probe
    built anew for each seed.

    Args:
        models: what :func:`kadv.testing.viewpoint_robustness` takes as a model.
        probes: probe names (:data:`kadv.probes.PROBES`); None: all of them.
        seeds: the probes' and the searches' seeds.
        envelope, radii, typical_views, fail_below, search_seeds: as
            :func:`kadv.testing.robustness_profile` takes them.
        pool: score every model also at the worst views the other models' searches found (same
            probe, seed and init views), so that each model's worst case is the worst over all the
            searches (:func:`kadv.testing.profile.pool_worst_views`); False: each its own search's.
        progress: print a line per probe, model and seed as each finishes.
        options: more of :func:`kadv.testing.robustness_profile`'s arguments (``budget_passes``,
            ``artifacts``, ``lighting``, ...).

    Raises:
        RobustnessInputError: an unknown probe (listing the probes), no seeds, or a bad model.
    """
    from kadv.catalogue.probes import probe_scene

    probes, seeds, loaded = _checked_inputs(models, probes, seeds)
    names = [model.name for model in loaded]
    settings = profile_settings(radii, envelope, typical_views, fail_below, options, "scorecard", search_seeds)
    results: dict[str, dict[str, Profile]] = {}
    for probe in probes:
        profiles: dict[str, list[Profile]] = {name: [] for name in names}
        for seed in seeds:
            built = probe_scene(probe, seed)
            runs = [seed_run(model, built, settings, seed) for model in loaded]
            if pool and len(runs) > 1:
                pool_worst_views(runs, settings.radii)
            for model, run in zip(loaded, runs):
                profile = settings.profile([run], save_worst_pictures(run, settings.radii))
                profiles[model.name].append(profile)
                if progress:
                    worst = " ".join(f"{v:.3f}" for v in profile.worst)
                    print(
                        f"{probe} x {model.name}, seed {seed}: worst {worst}, worst-case area "
                        f"{profile.worst_score:.3f}, typical area {profile.score:.3f}",
                        flush=True,
                    )
        results[probe] = {name: Profile.merge(profiles[name]) for name in names}
    return Scorecard(names, probes, results)
