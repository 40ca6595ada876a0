"""The probe scorecard: every model's robustness profile on every probe scene, as one table, one
ranking and one picture."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kadv.testing.inputs import RobustnessInputError
from kadv.testing.profile import (
    DEFAULT_RADII,
    FAIL_BELOW,
    TYPICAL_VIEWS,
    Profile,
    profile_settings,
    save_profile_panels,
)
from kadv.testing.session import current

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
        suite_scores: per model, its suite score on the scorecard's suite
            (:meth:`kadv.bench.SuiteScore.to_dict`).
        pooled: per model, its pooled worst case (overall, then per radius): the mean over cells of
            the lowest of its own worst and its delta1 at the other models' worst poses; empty with
            one model. It depends on which models ran together, so it is never the suite score.
        suite: the scorecard's suite: its name and hash.
    """

    models: list[str]
    probes: list[str]
    results: dict[str, dict[str, Profile]]
    suite_scores: dict[str, dict] = field(default_factory=dict)
    pooled: dict[str, list[float]] = field(default_factory=dict)
    suite: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The models, probes, every profile (:meth:`Profile.to_dict`), the suite scores and the
        pooled worst cases, as plain JSON values."""
        results = {probe: {model: p.to_dict() for model, p in row.items()} for probe, row in self.results.items()}
        return {
            "models": list(self.models),
            "probes": list(self.probes),
            "results": results,
            "suite_scores": self.suite_scores,
            "pooled": self.pooled,
            "suite": self.suite,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Scorecard:
        """The scorecard :meth:`to_dict` wrote: its rankings and table computed again."""
        results = {
            probe: {model: Profile.from_dict(p) for model, p in row.items()} for probe, row in data["results"].items()
        }
        return cls(
            list(data["models"]),
            list(data["probes"]),
            results,
            data.get("suite_scores", {}),
            data.get("pooled", {}),
            data.get("suite", {}),
        )

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
            f"delta1 after {_fits(self.results[self.probes[0]])}; agreement: the "
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
        notes += self._suite_lines(radii)
        rankings = [self.ranking("worst"), self.ranking("typical")]
        if len(self.models) > 1:
            rankings += self.differences("worst") + self.differences("typical")
        return "\n".join(lines) + "\n\n" + "\n".join(notes) + "\n\n" + "\n".join(rankings)

    def _suite_lines(self, radii) -> list[str]:
        """Each model's suite score on the scorecard's suite (95% over search seeds) and, with two
        models or more, its pooled worst case."""
        if not self.suite_scores:
            return []
        per = ", ".join(f"{d:g}°/{m:g} m" for d, m in radii)
        lines = [
            f"suite score (suite {self.suite.get('name')} {str(self.suite.get('hash'))[:12]}: the worst delta1, mean "
            f"over the cells of every probe, seed and init view; per radius {per}; 95% over the search seeds):"
        ]
        for model in self.models:
            score = self.suite_scores[model]
            low, high = score["overall_interval"]
            interval = "n/a: one search seed" if math.isnan(low) else f"95% {low:.3f}-{high:.3f}"
            radius_text = " / ".join(f"{v:.3f}" for v in score["per_radius"])
            line = f"- {model}: {score['overall']:.3f} ({interval}); {radius_text}"
            if model in self.pooled:
                pooled = self.pooled[model]
                line += f"; pooled worst {pooled[0]:.3f} ({' / '.join(f'{v:.3f}' for v in pooled[1:])})"
            lines.append(line)
        if self.pooled:
            lines.append(
                "pooled worst: each model also scored at the other models' worst poses (it depends on which "
                "models ran together: a column of its own, never the suite score)"
            )
        return lines

    def save_png(self, path: str | Path) -> Path:
        """One panel per probe: each model's worst (solid) and typical (dashed) delta1 against the
        radius, with bands over the seeds."""
        panels = {
            probe: {f"{model} {profile.score:.2f}": profile for model, profile in self.results[probe].items()}
            for probe in self.probes
        }
        return save_profile_panels(path, panels)


def _fits(profiles: dict[str, Profile]) -> str:
    """How the models' delta1 met the ground truth: ``scale_shift alignment in disparity space``,
    or per model where their output kinds are fitted differently."""
    fits = {name: f"{p.alignment} alignment in {p.space} space" for name, p in profiles.items()}
    if len(set(fits.values())) == 1:
        return next(iter(fits.values()))
    return ", ".join(f"{fit} ({name})" for name, fit in fits.items())


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


def _check_alignment(models: list, alignment: str | None) -> None:
    """Refuse, as a :class:`RobustnessInputError`, an alignment one of ``models``' kinds does not allow."""
    from kadv.losses.align import check_alignment, kind_fit

    try:
        for model in models:
            check_alignment(
                kind_fit(model.output_kind, alignment=alignment)[1], model.output_kind, f"model {model.name}"
            )
    except ValueError as error:
        raise RobustnessInputError(str(error)) from None


def _pooled(suite, runs: dict, models: list) -> dict[str, list[float]]:
    """Each model's pooled worst delta1, overall then per radius: scored at every model's worst poses."""
    from kadv.bench import pooled_worst

    found = pooled_worst(suite, {name: run.entry for name, run in runs.items()}, {m.name: m for m in models})
    return {name: [overall, *per_radius] for name, (overall, per_radius) in found.items()}


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
    """Profile each model on each probe scene, each probe built at each seed: a suite run.

    The probes at the seeds are frozen into a suite (:func:`kadv.testing.runs.probe_suite`: init
    views by a model-free rule, so every model starts from the same views); each model runs it as
    an entry, under ``search_seeds`` search seeds per init view (its units and ``entry.json`` under
    ``artifacts/entries/``, the suite at ``artifacts/suite-<hash>.json``); typical views are drawn
    beside each init view. The profiles, areas and rankings come from those runs, and the suite
    score (:func:`kadv.bench.suite_score`) stands beside them.

    Args:
        models: what :func:`kadv.testing.viewpoint_robustness` takes as a model.
        probes: probe names (:data:`kadv.probes.PROBES`); None: all of them.
        seeds: the seeds the probes are built at (each a scene of the suite).
        envelope, radii, typical_views, fail_below, search_seeds: as
            :func:`kadv.testing.robustness_profile` takes them (the envelope a preset's name).
        pool: with two models or more, also score every model at the worst poses the others found
            (:func:`kadv.bench.pooled_worst`), as a column of its own beside each model's worst.
        progress: print a line per probe scene and model as each finishes.
        options: more of :func:`kadv.testing.robustness_profile`'s arguments (``budget_passes``,
            ``artifacts``, ``lighting``, ...).

    Raises:
        RobustnessInputError: an unknown probe (listing the probes), no seeds, or a bad model or setting.
    """
    import tempfile

    from kadv.bench import pool_units, suite_score
    from kadv.testing.runs import probe_suite, profiles, run_model

    probes, seeds, loaded = _checked_inputs(models, probes, seeds)
    settings = profile_settings(radii, envelope, typical_views, fail_below, options, "scorecard", search_seeds)
    _check_alignment(loaded, settings.checked.alignment)
    suite = probe_suite(probes, seeds, settings)
    folder = settings.checked.artifacts or current().artifacts or tempfile.mkdtemp(prefix="kadv-")
    suite.save(Path(folder) / f"suite-{suite.hash[:12]}.json")
    runs = {model.name: run_model(suite, model, settings.typical_views, Path(folder), progress) for model in loaded}
    results = {probe: {} for probe in probes}
    for name, run in runs.items():
        for probe, profile in profiles(suite, run, probes, settings.fail_below).items():
            results[probe][name] = profile
    scores = {name: suite_score(suite, pool_units(suite, [run.entry])).to_dict() for name, run in runs.items()}
    pooled = _pooled(suite, runs, loaded) if pool and len(loaded) > 1 else {}
    names = [model.name for model in loaded]
    return Scorecard(names, probes, results, scores, pooled, {"name": suite.name, "hash": suite.hash})
