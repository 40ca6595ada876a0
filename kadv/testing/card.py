"""The probe scorecard: every model's robustness profile on every probe scene, as one table, one
ranking and one picture."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kadv.testing.inputs import RobustnessInputError
from kadv.testing.profile import DEFAULT_RADII, Profile, robustness_profile, save_profile_panels

__all__ = ["Scorecard", "scorecard"]


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

    def seed_scores(self, model: str) -> list[float]:
        """The model's score under each seed, the mean over the probes."""
        return np.mean([self.results[probe][model].scores for probe in self.probes], axis=0).tolist()

    def ranking(self) -> str:
        """``ranking: a (0.61) > b (0.55)``: the models by mean score, highest first; ``=`` joins
        neighbours whose bands over the seeds (min to max) overlap: tied."""
        bands = {model: self.seed_scores(model) for model in self.models}
        order = sorted(self.models, key=lambda model: -float(np.mean(bands[model])))
        text = f"ranking: {order[0]} ({np.mean(bands[order[0]]):.3f})"
        for better, worse in itertools.pairwise(order):
            tied = min(bands[better]) <= max(bands[worse])
            text += f" {'=' if tied else '>'} {worse} ({np.mean(bands[worse]):.3f})"
        if len(order) > 1 and " = " in text:
            text += "; '=': their scores' bands over the seeds overlap (tied)"
        return text

    def markdown(self) -> str:
        """Per probe and model: the worst delta1 at each radius, the failure rate at the largest,
        the score (mean ± spread over the seeds); the models' mean scores; the ranking."""
        radii = self.results[self.probes[0]][self.models[0]].radii
        largest = f"{radii[-1][0]:g}°/{radii[-1][1]:g} m"
        lines = [
            "| probe | model | "
            + " | ".join(f"worst delta1 {d:g}°/{m:g} m" for d, m in radii)
            + f" | failure rate {largest} | score (typical area) |",
            "|---|---|" + "---|" * (len(radii) + 2),
        ]
        for probe in self.probes:
            for model in self.models:
                profile = self.results[probe][model]
                worst = " | ".join(f"{v:.3f}" for v in profile.worst)
                lines.append(
                    f"| {probe} | {model} | {worst} | {profile.failure_rate[-1]:.0%} | "
                    f"{profile.score:.3f} ± {profile.score_spread:.3f} |"
                )
        for model in self.models:
            scores = self.seed_scores(model)
            blank = " | ".join([""] * (len(radii) + 1))
            lines.append(f"| **mean** | {model} | {blank} | **{np.mean(scores):.3f} ± {np.ptp(scores):.3f}** |")
        return "\n".join(lines) + "\n\n" + self.ranking()

    def save_png(self, path: str | Path) -> Path:
        """One panel per probe: each model's worst (solid) and typical (dashed) delta1 against the
        radius, with bands over the seeds."""
        panels = {
            probe: {f"{model} {profile.score:.2f}": profile for model, profile in self.results[probe].items()}
            for probe in self.probes
        }
        return save_profile_panels(path, panels)


def scorecard(
    models: list,
    probes: list[str] | None = None,
    *,
    seeds=(0,),
    envelope="upright",
    radii=DEFAULT_RADII,
    progress: bool = False,
    **options,
) -> Scorecard:
    """Profile each model on each probe scene (:func:`kadv.testing.robustness_profile`), each probe
    built anew for each seed.

    Args:
        models: what :func:`kadv.testing.viewpoint_robustness` takes as a model.
        probes: probe names (:data:`kadv.probes.PROBES`); None: all of them.
        seeds: the probes' and the searches' seeds.
        envelope, radii: as :func:`kadv.testing.robustness_profile` takes them.
        progress: print a line per probe, model and seed as each finishes.
        options: more of :func:`kadv.testing.robustness_profile`'s arguments (``budget_evaluations``,
            ``artifacts``, ``lighting``, ...).

    Raises:
        RobustnessInputError: an unknown probe (listing the probes), no seeds, or a bad model.
    """
    from kadv.models import DepthModel
    from kadv.scenes.probes import PROBES, probe_scene
    from kadv.testing.inputs import resolve_model
    from kadv.testing.profile import check_radii

    probes = list(PROBES) if probes is None else list(probes)
    unknown = [name for name in probes if name not in PROBES]
    if unknown:
        raise RobustnessInputError(f"no probe scene {unknown[0]!r}; the probes are: {', '.join(PROBES)}")
    if not models:
        raise RobustnessInputError("scorecard needs at least one model")
    seeds = tuple(seeds)
    if not seeds:
        raise RobustnessInputError("seeds is empty: give at least one seed")
    radii = check_radii(radii)
    loaded: list[DepthModel] = [resolve_model(model) for model in models]
    names = [model.name for model in loaded]
    if len(set(names)) != len(names):
        raise RobustnessInputError(f"models: each must have its own name, got {names}")
    results: dict[str, dict[str, Profile]] = {}
    for probe in probes:
        runs: dict[str, list[Profile]] = {name: [] for name in names}
        for seed in seeds:
            built = probe_scene(probe, seed)
            for model in loaded:
                profile = robustness_profile(
                    model, built, radii=radii, envelope=envelope, seeds=(seed,), progress=False, **options
                )
                runs[model.name].append(profile)
                if progress:
                    worst = " ".join(f"{v:.3f}" for v in profile.worst)
                    print(f"{probe} x {model.name}, seed {seed}: worst {worst}, score {profile.score:.3f}", flush=True)
        results[probe] = {name: Profile.merge(profiles) for name, profiles in runs.items()}
    return Scorecard(names, probes, results)
