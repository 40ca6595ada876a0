"""Robustness against the size of the camera's move: how far must the camera move, within the poses
a real camera takes, before the model fails?

:func:`robustness_profile` searches nested radii (degrees, metres) around a scene's init views
within a camera envelope, and reports per radius the worst view the default search finds and the
typical view (uniform draws), then one score: the area under the typical curve, which ranks models
because every model is scored on the same drawn views (the worst view is each model's own search's,
and its area varies with the search; docs/testing.md measures both). Adversarial robustness reports
accuracy over the perturbation's size in the same way; RoboDepth averages over severities.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from kadv.attack.profile import Profile, curve_area, save_profile_panels
from kadv.attack.radii import (
    DEFAULT_RADII,
    FAIL_BELOW,
    SEARCH_SEED_STRIDE,
    TYPICAL_VIEWS,
    WARM_STARTS,
    SeedProfile,
    profile_views,
    radius_budgets,
    search_radii,
    warm_starts,
    worst_views,
)
from kadv.testing.inputs import RobustnessInputError
from kadv.testing.options import CheckOptions, Setup, check_radii, setup

__all__ = [
    "DEFAULT_RADII",
    "FAIL_BELOW",
    "PROFILE_KEYS",
    "SEARCH_SEED_STRIDE",
    "TYPICAL_VIEWS",
    "WARM_STARTS",
    "Profile",
    "ProfileSettings",
    "SeedProfile",
    "SeedRun",
    "curve_area",
    "profile_settings",
    "profile_views",
    "robustness_profile",
    "save_profile_panels",
    "save_worst_pictures",
    "search_radii",
    "seed_run",
    "warm_starts",
    "worst_views",
]

# what a profile takes beyond CheckOptions (whose radius and seed it replaces)
PROFILE_KEYS = ("radii", "envelope", "seeds", "typical_views", "fail_below", "search_seeds")


def robustness_profile(
    model,
    scene,
    *,
    radii=DEFAULT_RADII,
    envelope="upright",
    seeds=(0,),
    typical_views: int = TYPICAL_VIEWS,
    fail_below: float = FAIL_BELOW,
    search_seeds: int = 1,
    **options,
) -> Profile:
    """The model's :class:`Profile` on ``scene``: per radius, the worst and typical delta1 within it
    and the envelope, over the scene's init views and ``seeds``; deterministic for the seeds.

    Args:
        model, scene: as :func:`kadv.testing.viewpoint_robustness` takes them.
        radii: nested (degrees, metres) bounds on the move from each init view, increasing.
        envelope: a preset's name (``free``, ``upright``, ``handheld``, ``robot``) or an
            :class:`kadv.penalties.Envelope`.
        seeds: one profile run per seed (init views and searches); the score's spread is over them.
        typical_views: views drawn per init view and radius for the typical case.
        fail_below: a drawn view whose delta1 is below this counts as failed.
        search_seeds: searches per seed from the same init views (the first under the seed
            itself); two or more measure the search noise apart from the init views' spread.
        options: :class:`kadv.testing.CheckOptions`' other fields (``budget_passes``: per init
            view and radius on average for the worst case, split by ``radius_shares``;
            ``init_count``, ``size``, ``method``, ``loss``, ``lighting``, ``artifacts``, ``progress``).

    Raises:
        RobustnessInputError: bad radii, seeds, envelope, model, scene or setting, in one line.
    """
    settings = profile_settings(radii, envelope, typical_views, fail_below, options, "robustness_profile", search_seeds)
    seeds = tuple(seeds)
    if not seeds or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
        raise RobustnessInputError(f"seeds must be one or more integers >= 0, got {list(seeds)}")
    runs = [seed_run(model, scene, settings, seed) for seed in seeds]
    return settings.profile(runs, save_worst_pictures(runs[0], settings.radii))


@dataclass(frozen=True)
class ProfileSettings:
    """How a profile searches and draws (checked): the check's options, the radii, the search and
    its envelope, the typical views per init view and radius, the failure threshold, the searches
    per seed."""

    checked: CheckOptions
    radii: tuple[tuple[float, float], ...]
    config: object
    typical_views: int
    fail_below: float
    search_seeds: int = 1

    def profile(self, runs: list[SeedRun], pictures: list[str]) -> Profile:
        """The :class:`Profile` of one model's seed runs."""
        built = runs[0].built
        names = (built.model_name, built.scene_name, self.config.envelope.name)
        seeds = tuple(run.seed for run in runs)
        seeded = [run.seeded for run in runs]
        objective = built.study.objective
        return Profile.of(
            *names, self.radii, seeds, seeded, self.fail_below, pictures, objective.alignment, objective.metric_space
        )


def profile_settings(
    radii, envelope, typical_views, fail_below, options: dict, taker: str, search_seeds: int = 1
) -> ProfileSettings:
    """:class:`ProfileSettings` from a profile's arguments, or :class:`RobustnessInputError` naming
    the bad one (``taker``: the function that was given them)."""
    from kadv.attack import AttackConfig
    from kadv.penalties import get_envelope

    taken = sorted({"radius", "seed"} & set(options))
    if taken:
        raise RobustnessInputError(f"{taker} takes radii and seeds, not {' or '.join(taken)}")
    checked = CheckOptions.of(options, taker)
    radii = check_radii(radii)
    if not (isinstance(typical_views, int) and typical_views >= 2):
        raise RobustnessInputError(f"typical_views must be an integer >= 2, got {typical_views!r}")
    if not (isinstance(fail_below, (int, float)) and 0 < fail_below <= 1):
        raise RobustnessInputError(f"fail_below must be in (0, 1], got {fail_below!r}")
    if isinstance(search_seeds, bool) or not (isinstance(search_seeds, int) and search_seeds >= 1):
        raise RobustnessInputError(f"search_seeds must be an integer >= 1, got {search_seeds!r}")
    try:
        bounds = get_envelope(envelope)
        shares = checked.radius_shares
        shares = tuple(shares) if isinstance(shares, (list, tuple)) else shares  # another type: refused by key
        config = AttackConfig(checked.method, envelope=bounds, restarts=checked.restarts, radius_shares=shares)
        radius_budgets(checked.budget_passes, len(radii), shares)  # shares one a radius, refused here if not
    except ValueError as error:
        raise RobustnessInputError(str(error)) from None
    return ProfileSettings(checked, radii, config, typical_views, float(fail_below), search_seeds)


@dataclass
class SeedRun:
    """One model's profile run under one seed: what it searched with and what it found."""

    seed: int
    built: Setup
    views: list
    config: object
    seeded: SeedProfile


def seed_run(model, scene, settings: ProfileSettings, seed: int) -> SeedRun:
    """The :class:`SeedRun` of ``model`` on ``scene`` under ``seed``, or
    :class:`RobustnessInputError` in one line."""
    from kadv.attack.init_views import InitViewError, fit_into_envelope

    built = setup(model, scene, dataclasses.replace(settings.checked, seed=seed))
    try:
        config = dataclasses.replace(settings.config, budget_passes=built.budget)
        views = [fit_into_envelope(built.renderer, v, config.envelope, built.penalty.margin) for v in built.views]
    except InitViewError as error:
        raise RobustnessInputError(f"scene {built.scene_name!r}: {error}") from None
    except ValueError as error:  # a budget too small for the method
        raise RobustnessInputError(f"budget_passes={built.budget}: {error}") from None
    seeded = profile_views(
        built.study,
        views,
        config,
        settings.radii,
        seed,
        settings.typical_views,
        settings.fail_below,
        settings.checked.progress,
        search_seeds=settings.search_seeds,
    )
    return SeedRun(seed, built, views, config, seeded)


def save_worst_pictures(run: SeedRun, radii) -> list[str]:
    """The four-panel picture of the worst view found within each radius, in the run's folder."""
    from kadv.report.outputs import save_view_picture

    pictures = []
    for k, ((degrees, metres), (init, record)) in enumerate(zip(radii, run.seeded.worst_views)):
        label = f"worst within {degrees:g}°, {metres:g} m"
        path = run.built.folder / f"{run.built.stem}-{run.config.envelope.name}-radius{k}.png"
        pictures.append(str(save_view_picture(path, run.built.render, init, record, label)))
    return pictures
