"""The search across nested radii (degrees, metres) around a scene's init views: each radius
searched in turn, smallest first, warm-started from the worst views found within the smaller ones,
and per radius the typical view (uniform draws) beside the worst; what a profile
(:class:`~kadv.attack.profile.Profile`) is made of, and what ``kadv-attack attack.radii=...`` runs."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch

from kadv.attack.records import select_top_views, worst_record
from kadv.attack.search import SearchContext, positive_shares
from kadv.attack.study import Study
from kadv.geometry import perturb_world_T_cam

__all__ = [
    "DEFAULT_RADII",
    "FAIL_BELOW",
    "SEARCH_SEED_STRIDE",
    "TYPICAL_VIEWS",
    "WARM_STARTS",
    "SeedProfile",
    "draw_typical",
    "profile_views",
    "radius_budgets",
    "ramp_shares",
    "search_radii",
    "warm_starts",
    "worst_views",
]

DEFAULT_RADII = ((5.0, 0.1), (15.0, 0.3), (45.0, 1.0))  # (degrees, metres), nested
# A drawn view fails below this delta1: the highest threshold that the init views' delta1 stays above
# and under which a noisier model never fails less (benchmarks/ranking.py --parts threshold)
FAIL_BELOW = 0.6
TYPICAL_VIEWS = 16  # uniform draws per init view and radius
WARM_STARTS = 2  # the worst separated views within the smaller radii that a search at the next starts from
# search seed j of a profile's seed s (init views fixed) is s + SEARCH_SEED_STRIDE * j
SEARCH_SEED_STRIDE = 10_000
_DRAW_ROUNDS = 32  # rounds of 4 x typical_views draws at most, for the envelope to keep enough


def draw_typical(study: Study, init, config, seed: int, index: int, count: int) -> tuple[list[float], int]:
    """delta1 of the valid views among ``count`` drawn uniformly (Sobol) from the radius and the
    envelope around ``init``, and the model passes spent on them."""
    from scipy.stats import qmc  # scipy loads only where views are drawn

    objective = study.objective
    context = SearchContext(objective, study.differentiable, init, *study.settings.size, config)
    space = context.space
    sobol = qmc.Sobol(space.dims, scramble=True, seed=np.random.default_rng([seed, index, 7]))
    chosen = []
    # rejection keeps the draws uniform within the envelope; a tight envelope (robot's roll of 2
    # degrees in a 45-degree ball) keeps few of them, so the design is drawn on in rounds
    for _ in range(_DRAW_ROUNDS):
        params = space.sample(sobol.random(4 * count))
        poses = perturb_world_T_cam(context.base(len(params)).cpu(), params[:, :3], params[:, 3:6])
        inside = [reason is None for reason in config.envelope.figures(objective.renderer, poses).reasons()]
        chosen += list(params[torch.tensor(inside)])
        if len(chosen) >= count:
            break
    if not chosen:
        return [], 0
    chosen = torch.stack(chosen[:count])
    return [r.delta1 for r in context.evaluate(0, chosen) if r.valid], len(chosen)


@dataclass
class SeedProfile:
    """One seed's share of a :class:`Profile` (what :func:`profile_views` returns).

    Attributes:
        delta1_init: mean delta1 at the init views.
        typical, failure: per radius, as :class:`Profile`'s ``*_by_seed`` rows.
        draws: per radius, the delta1 of every valid drawn view.
        found: per radius and init view, the (init view, record) of the worst view found within
            that radius (by its own search).
        results: per radius, the attack's result within it.
        search_noise: per radius, the sd (ddof 1) of :attr:`worst` over the search seeds (empty: one).
        cost: per init view, the searches' passes and seconds over all radii, the draws' passes.
        agreement: per radius, as :class:`Profile`'s ``agreement_by_seed`` rows.
    """

    delta1_init: float
    typical: list[float]
    failure: list[float]
    draws: list[list[float]]
    found: list[list[tuple]]
    results: list
    search_noise: list[float] = dataclasses.field(default_factory=list)
    cost: dict[str, float] = dataclasses.field(default_factory=dict)
    agreement: list[list[int]] = dataclasses.field(default_factory=list)

    @property
    def carried(self) -> list[list[tuple]]:
        """Per radius and init view, the worst view within that radius or a smaller one (nested)."""
        rows, best = [], list(self.found[0])
        for row in self.found:
            best = [b if b[1].delta1 < f[1].delta1 else f for b, f in zip(best, row)]
            rows.append(best)
        return rows

    @property
    def worst(self) -> list[float]:
        """Per radius, the mean over init views of the worst delta1 within it: never rising."""
        return [float(np.mean([record.delta1 for _, record in row])) for row in self.carried]

    @property
    def worst_views(self) -> list[tuple]:
        """Per radius, the (init view, record) of the worst view within it, over the init views."""
        return [min(row, key=lambda pair: pair[1].delta1) for row in self.carried]


def worst_views(records: list, count: int, min_distance: float, min_angle_deg: float) -> list:
    """Up to ``count`` rankable records of lowest delta1 (the highest loss among ties), each
    separated from those chosen before it: the views a larger radius's search starts from."""
    return select_top_views(records, count, min_distance, min_angle_deg, order=lambda r: (r.delta1, -r.loss))


def ramp_shares(count: int) -> tuple[int, ...]:
    """The default split of a profile's passes over ``count`` nested radii: the k-th radius,
    smallest first, gets k shares (5°/0.1 m, 15°/0.3 m, 45°/1 m: a sixth, a third, a half). More
    passes lower the worst found, and its noise, most where the ball is largest; docs/attack.md,
    "The passes where the basins are", has the measurement that chose it."""
    return tuple(range(1, count + 1))


def radius_budgets(passes: int | None, count: int, shares: tuple[float, ...] | None = None) -> list[int | None]:
    """The pass budget of each of ``count`` nested radii, ``passes`` per radius on average: the
    total split in proportion to ``shares`` (one a radius; None: :func:`ramp_shares`; equal
    shares: equally), the budgets summing to the total, each at least 2 (the init view and one
    view more) where the total allows. None (no pass budget) stays None.

    Raises:
        ValueError: shares that are not one positive number a radius, in one line.
    """
    if passes is None:
        return [None] * count
    shares = ramp_shares(count) if shares is None else shares
    if len(shares) != count or not positive_shares(shares):
        raise ValueError(f"attack.radius_shares must be {count} positive numbers, one a radius, got {list(shares)}")
    total = passes * count
    bounds = [round(total * c) for c in np.cumsum(shares) / sum(shares)]
    budgets = [b - a for a, b in zip([0, *bounds[:-1]], bounds)]
    floor = min(2, passes)
    for k in range(count):
        while budgets[k] < floor:
            donor = max(range(count), key=lambda j: budgets[j])
            budgets[donor] -= 1
            budgets[k] += 1
    return budgets


def search_radii(
    study: Study,
    views: list,
    config,
    radii: tuple[tuple[float, float], ...],
    seed: int,
    progress: bool = False,
    searched: dict[int, object] | None = None,
    warm: int = WARM_STARTS,
    budgets: list[int | None] | None = None,
) -> list:
    """The ``study``'s search ``config`` within each radius, smallest first (its bounds set to the radius): each
    init view's search at a radius gets the ``warm`` worst separated views found within the smaller
    ones as warm starts (they lie within it; :class:`~kadv.attack.SearchContext`'s ``starts``).
    ``searched`` holds results already found at some radii (by index), used instead of searching.
    ``config.budget_passes`` is the passes a radius on average, split by ``config.radius_shares``
    (:func:`radius_budgets`), or each radius's pass budget is given (``budgets``). Returns one
    :class:`~kadv.attack.AttackResult` per radius."""
    results: list = []
    budgets = budgets or radius_budgets(config.budget_passes, len(radii), config.radius_shares)
    for k, (degrees, metres) in enumerate(radii):
        within = dataclasses.replace(config, max_angle_deg=degrees, max_distance=metres, budget_passes=budgets[k])
        result = (searched or {}).get(k)
        if result is None:
            starts = warm_starts(results, len(views), warm, config) if results else None
            result = study.attack(views, seed, within, starts=starts, progress=progress)
        results.append(result)
    return results


def warm_starts(results: list, views: int, count: int, config) -> dict[int, torch.Tensor]:
    """Per init view, the points (N, dims) of the pose space of the ``count`` worst separated views
    that the attack ``results`` found from it."""
    starts = {}
    for index in range(views):
        records = [r for result in results for r in result.views[index].records]
        chosen = worst_views(records, count, config.min_separation, config.min_separation_deg)
        dims = len(records[0].params) if records else 6
        starts[index] = torch.tensor([r.params for r in chosen], dtype=torch.float64).reshape(-1, dims)
    return starts


def profile_views(
    study: Study,
    views: list,
    config,
    radii: tuple[tuple[float, float], ...],
    seed: int,
    typical_views: int = TYPICAL_VIEWS,
    fail_below: float = FAIL_BELOW,
    progress: bool = False,
    searched: dict[int, object] | None = None,
    search_seeds: int = 1,
) -> SeedProfile:
    """One seed's profile of the init ``views`` in the ``study``: per radius, the search ``config`` (its bounds set to
    the radius, warm-started from the smaller radii: :func:`search_radii`) and ``typical_views``
    uniform draws per init view; the worst view carried from radius to radius (the radii are
    nested). ``searched`` holds results already found at some radii (by index), which are used
    instead of searching again. With ``search_seeds`` above 1, the search runs again under search
    seeds ``seed + SEARCH_SEED_STRIDE * j`` from the same init views, for its noise."""
    results = search_radii(study, views, config, radii, seed, progress, searched)
    out = SeedProfile(math.nan, [], [], [[] for _ in radii], [], [])
    draw_passes = 0
    for k, ((degrees, metres), result) in enumerate(zip(radii, results)):
        within = dataclasses.replace(config, max_angle_deg=degrees, max_distance=metres)
        typical: list[float] = []
        for i, view in enumerate(result.views):
            drawn, passes = draw_typical(study, view.init, within, seed, i, typical_views)
            typical += drawn
            draw_passes += passes
        if k == 0:
            out.delta1_init = float(np.mean([v.init_record.delta1 for v in result.views]))
        out.found.append([(view.init, worst_record(view.records)) for view in result.views])
        out.typical.append(float(np.mean(typical)) if typical else math.nan)
        out.failure.append(float(np.mean([d < fail_below for d in typical])) if typical else math.nan)
        out.draws[k] = typical
        out.results.append(result)
        out.agreement.append(_agreement_row([view.agreement for view in result.views]))
    budgets = [view.budget for result in results for view in result.views]
    out.cost = {
        "search_passes": sum(b.passes for b in budgets) / len(views),
        "search_seconds": sum(b.seconds for b in budgets) / len(views),
        "draw_passes": draw_passes / len(views),
    }
    if search_seeds > 1:
        worst = [out.worst] + [
            _worst_of(search_radii(study, views, config, radii, seed + SEARCH_SEED_STRIDE * j))
            for j in range(1, search_seeds)
        ]
        out.search_noise = np.std(worst, axis=0, ddof=1).tolist()
    return out


def _agreement_row(agreements: list) -> list[int]:
    """[runs that reached their worst, runs made, init views whose worst one run alone found]
    over the init views' agreements (:func:`kadv.attack.attack` gives every result one)."""
    return [sum(a.reached for a in agreements), sum(a.runs for a in agreements), sum(a.alone for a in agreements)]


def _worst_of(results: list) -> list[float]:
    """Per radius, the mean over init views of the worst delta1 within it or a smaller one."""
    lowest = [math.inf] * len(results[0].views)
    rows = []
    for result in results:
        lowest = [min(low, worst_record(view.records).delta1) for low, view in zip(lowest, result.views)]
        rows.append(float(np.mean(lowest)))
    return rows
